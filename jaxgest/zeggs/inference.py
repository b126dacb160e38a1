"""ZeroEGGS generation: speech + style example clip(s) -> gestures (zero-shot), blending, PCA edits, seeds.

``TrainedZeggs.generate(audio, styles, weights=None, seed=0, temperature=1.0, pca_edits=None) -> Motion``
(:func:`load` reads a workdir through :mod:`jaxgest.zeggs.workdir`; the model owns its compiled functions).
``audio``: a WAV/FLAC path or ``(samples, sample_rate)``; ``styles``: a Motion or BVH path, or a list of them.

1. speech features of the audio at the model rate, normalised with the training statistics;
2. each style clip is brought to the training rig at the model rate (:func:`jaxgest.motion.body.to_rig`:
   itself on the same rig, otherwise through the 21-joint body joint maps with the feet on the floor), its
   pose features normalised and encoded by the style encoder (posterior mean and log-variance), then
   sampled with ``temperature`` (one key per clip, ``fold_in(key(seed), i)``);
3. blending: ``e = sum_i w_i e_i`` with the weights as given (one per clip, finite; default ``1 / n``
   each), so weights (2, 0) give exactly ``2 e_1`` -- the paper scales embeddings as well as mixing them;
   ``normalize_weights=True`` divides by ``sum_i w_i`` instead (then the sum must be positive);
4. optional PCA edits of ``e`` (``workdir/pca.json``, see :mod:`jaxgest.zeggs.pca`);
5. the generator runs autoregressively from the first style frame's pose, facing +Z, for
   ``round(duration * model fps)`` frames; features become a Motion on the training rig, then it is put on
   the first style clip's rig (``to_rig`` again, feet on the floor when the rig differs) at its frame rate
   with ``round(duration * fps)`` frames.

References: Ghorbani et al. 2023, §3 (inference from an example clip), §5.1 (zero-shot), §5.2.1
(blending by linear interpolation of embeddings), §5.2.2 (PCA control).
"""

from __future__ import annotations

import os
import pathlib
from typing import Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.runtime.errors import DataError, JaxgestError
from jaxgest.motion import bvh
from jaxgest.motion.body import to_rig
from jaxgest.motion.skeleton import Motion
from jaxgest.zeggs import features, quant
from jaxgest.zeggs.generator import input_scale
from jaxgest.zeggs.inputs import (  # noqa: F401 (StyleLike, bucket_length: re-exported)
    StyleLike, as_motions, audio_input, bucket_length, validate_weights)
from jaxgest.zeggs.model import apply_fns, calibrate
from jaxgest.zeggs.style_encoder import sample_style
from jaxgest.zeggs.workdir import TrainedWorkdir, load_workdir


class TrainedZeggs:
    """A trained ZeroEGGS model loaded from a workdir (see :func:`load`).

    Attributes: ``cfg`` (:class:`jaxgest.zeggs.config.Config`), ``params``, ``pose_stats``,
    ``speech_stats``, ``reference`` (the training rig), ``meta`` (config.json), ``step`` (the checkpoint
    step), ``pose_mean`` / ``pose_std`` (device arrays) and ``fns`` (its jitted functions, compiled on first
    use with ``cfg.inference.compiler_options``; they live as long as this object).
    """

    def __init__(self, loaded: TrainedWorkdir, workdir=None):
        self.workdir = pathlib.Path(workdir) if workdir is not None else None
        self.cfg, self.meta, self.step = loaded.cfg, loaded.meta, loaded.step
        self.pose_stats, self.speech_stats, self.reference = loaded.pose_stats, loaded.speech_stats, loaded.reference
        self.params = jax.tree_util.tree_map(jnp.asarray, loaded.params)
        self.pose_mean = jnp.asarray(self.pose_stats.mean, jnp.float32)
        self.pose_std = jnp.asarray(self.pose_stats.std, jnp.float32)
        self.input_scale = input_scale(self.cfg.model, self.pose_mean, self.pose_std)  # inputs: one std per group
        self.fns = apply_fns(self.cfg.model, self.cfg.inference.compiler_options)
        self.quantized = {}  # weight format -> the params with the generator's decoder in that format

    def encode_style(self, params, style, mask):
        """Style posterior of ``(b, S, P)`` clips; lengths padded (masked) to a bucket: few compilations."""
        S = style.shape[1]
        L = bucket_length(S)
        style = jnp.pad(jnp.asarray(style), ((0, 0), (0, L - S), (0, 0)))
        mask = jnp.pad(jnp.asarray(mask, bool), ((0, 0), (0, L - S)))
        return self.fns["encode_style"](params, style, mask)

    def encode_speech(self, params, speech):
        """Speech embeddings ``(b, F, D_S)`` of normalised speech features ``(b, F, 81)``."""
        return self.fns["encode_speech"](params, speech)

    def run_generator(self, params, s_emb, e, y0, r0, q0, f, mean, std, weight_format: str = "fp32"):
        """The generator over ``s_emb (b, F, D_S)``; F padded to a bucket (the generator is causal: frames
        after F do not change frames before it) and the output cut back to F frames. ``weight_format``
        ``bf16`` / ``int8``: the decoder's kernels in that format (:mod:`jaxgest.zeggs.quant`; converted once
        per model object and format)."""
        F = s_emb.shape[1]
        L = bucket_length(F)
        s_emb = jnp.pad(s_emb, ((0, 0), (0, L - F), (0, 0)))
        if quant.check_format(weight_format) != "fp32":
            if weight_format not in self.quantized:
                means = calibrate(self.cfg.model, params, *self.calibration_inputs(params))
                self.quantized[weight_format] = quant.quantize_params(params, weight_format, input_means=means)
            params = self.quantized[weight_format]
        out = self.fns["generate"](params, s_emb, e, y0, r0, q0, f, mean, std)
        return {k: v[:, :F] for k, v in out.items()}

    def calibration_inputs(self, params, frames: int = 256) -> tuple:
        """Generator inputs of the weight formats' bias correction (:func:`jaxgest.zeggs.model.calibrate`):
        the neutral request -- the mean speech frame (normalised features 0), style embedding 0 (the
        prior's mean), the mean pose, facing forward -- for ``frames`` frames; independent of any request."""
        m = self.cfg.model
        s_emb = self.encode_speech(params, jnp.zeros((1, frames, self.speech_stats.mean.shape[-1]), jnp.float32))
        q0 = jnp.asarray([[1.0, 0.0, 0.0, 0.0]], jnp.float32)
        return (s_emb, jnp.zeros((1, m.style_embedding), jnp.float32), jnp.zeros((1, m.pose_dim), jnp.float32),
                jnp.zeros((1, 3), jnp.float32), q0, jnp.asarray([[0.0, 0.0, 1.0]], jnp.float32), self.pose_mean,
                self.pose_std)

    # -- pieces ------------------------------------------------------------------------------------------
    def style_features(self, style: Motion) -> np.ndarray:
        """Pose features ``(F, P)`` of a style clip on the training rig at the model rate, normalised as the
        style encoder's input (per-channel mean, one std per group: ``cfg.model.input_norm``)."""
        return (self.pose_features(style) * np.asarray(self.input_scale)[None]).astype(np.float32)

    def pose_features(self, style: Motion) -> np.ndarray:
        """Pose features ``(F, P)`` of a clip on the training rig at the model rate, normalised per channel
        (the generator's output normalisation, in which it takes its initial pose)."""
        model, min_seconds = self.cfg.model, self.cfg.inference.min_style_seconds
        try:
            m = to_rig(style, self.reference, fps=model.fps)
        except JaxgestError as e:  # e.g. a rig that matches no joint map: name the clip
            raise type(e)(f"{style.name or 'style clip'}: {e}") from None
        if m.num_frames < max(model.style_min_frames, int(min_seconds * model.fps)):
            raise DataError(f"{style.name or 'style clip'}: {style.duration:.2f} s is too short for a style "
                            f"example (at least {min_seconds} s)")
        return self.pose_stats.normalize(features.extract_features(m)["features"]).astype(np.float32)

    def style_posterior(self, style: Motion):
        """``(mu, logvar)`` each ``(D_e,)`` of one style clip."""
        x = self.style_features(style)
        mu, logvar = self.encode_style(self.params, jnp.asarray(x)[None], jnp.ones((1, len(x)), bool))
        return np.asarray(mu[0]), np.asarray(logvar[0])

    def style_embedding(self, styles: Sequence[Motion], *, weights=None, seed: int = 0,
                        temperature: Optional[float] = None,
                        pca_edits: Optional[dict] = None, normalize_weights: bool = False) -> np.ndarray:
        """The blended (``sum_i w_i e_i``; PCA-edited) style embedding ``(D_e,)`` (``temperature`` None:
        ``cfg.inference.temperature``)."""
        temperature = self.cfg.inference.temperature if temperature is None else temperature
        if not styles:
            raise JaxgestError("at least one style clip is needed")
        w = validate_weights(weights, len(styles), normalize=normalize_weights)
        if not np.isfinite(temperature) or temperature < 0:
            raise JaxgestError(f"temperature must be finite and >= 0, got {temperature}")
        key = jax.random.key(seed)
        es = []
        for i, s in enumerate(styles):
            mu, logvar = self.style_posterior(s)
            e = sample_style(jnp.asarray(mu)[None], jnp.asarray(logvar)[None], jax.random.fold_in(key, i),
                             float(temperature))
            es.append(np.asarray(e[0], np.float64))
        e = np.tensordot(w, np.stack(es), axes=1)
        if pca_edits:
            from jaxgest.zeggs.pca import StylePCA

            if self.workdir is None:
                raise JaxgestError("PCA edits need the model's workdir (its pca.json)")
            e = StylePCA.load(self.workdir / "pca.json").edit(e, pca_edits)
        return e.astype(np.float32)

    def speech(self, audio, sr: Optional[int] = None) -> tuple[np.ndarray, float]:
        """Normalised speech features ``(F, 81)`` at the model rate and the audio duration (s)."""
        from jaxgest.audio import load_audio, speech_features

        if isinstance(audio, (str, os.PathLike)):
            y, sr = load_audio(audio)
        else:
            y = np.asarray(audio, np.float32)
            if sr is None:
                raise JaxgestError("an audio array needs its sample rate")
        duration = len(y) / float(sr)
        feats = speech_features(y, sr=sr, fps=self.cfg.model.fps, loudness=self.cfg.model.loudness,
                                method=self.cfg.model.speech_features)
        if len(feats) < 2:
            raise DataError(f"{audio if isinstance(audio, (str, pathlib.Path)) else 'audio'}: "
                            f"{duration:.3f} s of audio is too short to generate from")
        return self.speech_stats.normalize(feats).astype(np.float32), duration

    # -- generation --------------------------------------------------------------------------------------
    def generate(self, audio, styles, *, weights=None, seed: int = 0,
                 temperature: Optional[float] = None,
                 pca_edits: Optional[dict] = None, sr: Optional[int] = None, name: str = "generated",
                 normalize_weights: bool = False, weight_format: str = "fp32") -> Motion:
        """Gestures for ``audio`` in the (blended) style of ``styles``; a Motion on the first style clip's rig.

        ``audio``: a WAV/FLAC path or ``(samples, sample_rate)`` (or samples with ``sr``); ``styles``: a
        Motion or BVH path, or a list of them (module docstring for ``weights``, ``seed``, ``temperature``,
        ``pca_edits``); ``weight_format``: ``fp32`` (default), ``bf16`` or ``int8`` generator weights (not
        the blend ``weights``; see :mod:`jaxgest.zeggs.quant`)."""
        if weight_format not in quant.WEIGHT_FORMATS:
            raise JaxgestError(f"weight format must be one of {', '.join(quant.WEIGHT_FORMATS)}, "
                               f"got {weight_format!r}")
        styles = as_motions(styles)
        audio, sr = audio_input(audio, sr)
        e = self.style_embedding(styles, weights=weights, seed=seed, temperature=temperature, pca_edits=pca_edits,
                                 normalize_weights=normalize_weights)
        speech, duration = self.speech(audio, sr=sr)
        first = self.pose_features(styles[0])
        F = speech.shape[0]
        s_emb = self.encode_speech(self.params, jnp.asarray(speech)[None])
        q0 = jnp.asarray([[1.0, 0.0, 0.0, 0.0]], jnp.float32)
        out = self.run_generator(self.params, s_emb, jnp.asarray(e)[None], jnp.asarray(first[:1]),
                                 jnp.zeros((1, 3), jnp.float32), q0, jnp.asarray([[0.0, 0.0, 1.0]], jnp.float32),
                                 self.pose_mean, self.pose_std, weight_format=weight_format)
        pose = self.pose_stats.denormalize(np.asarray(out["pose"][0], np.float64))
        root_p = np.asarray(out["root_position"][0], np.float64)
        root_q = np.asarray(out["root_rotation"][0], np.float64)
        fps = self.cfg.model.fps
        template = self.reference.replace(rotations=np.repeat(self.reference.rotations[:1], F, 0),
                                          translations=np.repeat(self.reference.translations[:1], F, 0), fps=fps)
        motion = features.features_to_motion(pose, template, root_p, root_q, fps=fps, name=name)
        target = styles[0]
        return to_rig(motion, target, fps=target.fps, frames=max(1, int(round(duration * target.fps))))


def load(workdir):
    """The trained ZeroEGGS model of ``workdir``, read now (a long-lived caller keeps the returned model,
    which also keeps its compiled functions): a :class:`TrainedZeggs`, or for a workdir written by
    ``jaxgest zeggs import-official`` an :class:`jaxgest.zeggs.official.OfficialZeggs` (same ``generate``)."""
    from jaxgest.zeggs.official import is_official, load as load_official

    if is_official(workdir):
        return load_official(workdir)
    return TrainedZeggs(load_workdir(workdir), workdir)


load_model = load  # the name the CLI and older callers use
