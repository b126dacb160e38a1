"""ZeroEGGS generation: speech + style example clip(s) -> gestures (zero-shot), blending, PCA edits, seeds.

``ZeggsModel.generate(audio, styles, weights=None, seed=0, temperature=1.0, pca_edits=None) -> Motion``:

1. speech features of the audio at the model rate, normalised with the training statistics;
2. each style clip is brought to the training rig (directly when it is the same rig, otherwise through the
   21-joint body joint maps), resampled to the model rate, its pose features normalised and encoded by the
   style encoder (posterior mean and log-variance), then sampled with ``temperature`` (one key per clip,
   ``fold_in(PRNGKey(seed), i)``);
3. blending: ``e = sum_i w_i e_i`` with the weights as given (one per clip, finite; default ``1 / n``
   each), so weights (2, 0) give exactly ``2 e_1`` -- the paper scales embeddings as well as mixing them;
   ``normalize_weights=True`` divides by ``sum_i w_i`` instead (then the sum must be positive);
4. optional PCA edits of ``e`` (``workdir/pca.json``, see :mod:`jaxgest.zeggs.pca`);
5. the generator runs autoregressively from the first style frame's pose, facing +Z, for
   ``round(duration * model fps)`` frames; features become a Motion on the training rig, then it is mapped
   to the first style clip's rig and resampled to its frame rate with ``round(duration * fps)`` frames.

References: Ghorbani et al. 2023, §3 (inference from an example clip), §5.1 (zero-shot), §5.2.1
(blending by linear interpolation of embeddings), §5.2.2 (PCA control).
"""

from __future__ import annotations

import functools
import pathlib
from typing import Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.errors import DataError, JaxgestError
from jaxgest.motion import body as B
from jaxgest.motion.datasets import fit_frames, resample_motion
from jaxgest.motion.skeleton import Motion
from jaxgest.zeggs import features as Fe
from jaxgest.zeggs.generator import input_scale
from jaxgest.zeggs.steps import ZeggsModel
from jaxgest.zeggs.style_encoder import sample_style

MIN_STYLE_SECONDS = 0.5  # the shortest style example accepted (frames at the model rate below this are too few)


# Config fields added after models were trained with the old behaviour: a workdir whose config.json lacks
# one was trained with this value (the dataclass default is the new behaviour).
LEGACY_DEFAULTS = {"loudness": False, "input_norm": "channel"}


def legacy_config(cfg, stored: dict):
    """``cfg`` with the old behaviour of every field missing from a workdir's stored config dict."""
    missing = {k: v for k, v in LEGACY_DEFAULTS.items() if k not in stored}
    return cfg.replace(**missing) if missing else cfg


def validate_weights(weights, count: int, *, normalize: bool = False) -> np.ndarray:
    """Blend weights as an array: one per style clip, finite (default ``1 / count`` each).

    ``normalize=True``: divided by their sum, which must then be positive.
    References: Ghorbani et al. 2023, §5.2.1 (blending and scaling of style embeddings).
    """
    if weights is None:
        return np.full(count, 1.0 / count)
    w = np.asarray(list(weights), np.float64)
    if w.ndim != 1 or len(w) != count:
        raise JaxgestError(f"blend weights: got {w.size} weight(s) for {count} style clip(s)")
    if not np.all(np.isfinite(w)):
        raise JaxgestError(f"blend weights must be finite, got {w.tolist()}")
    if normalize:
        if w.sum() <= 0:
            raise JaxgestError(f"normalised blend weights must have a positive sum, got {w.tolist()}")
        w = w / w.sum()
    return w


def to_rig(motion: Motion, reference: Motion) -> Motion:
    """``motion`` on ``reference``'s rig: itself when the rigs match, else retargeted via the body maps."""
    if motion.skeleton.names == reference.skeleton.names:
        return motion
    body = B.retarget_to_body(motion)
    template = reference.replace(rotations=reference.rotations[:1], translations=reference.translations[:1])
    return B.retarget_from_body(body, template)


class ZeggsModel_:
    """A trained ZeroEGGS model loaded from a workdir (see :func:`load_model`)."""

    def __init__(self, workdir):
        from jaxgest.zeggs.train import load_workdir

        self.workdir = pathlib.Path(workdir)
        (self.cfg, params, self.pose_stats, self.speech_stats, self.reference, self.meta) = load_workdir(workdir)
        self.cfg = legacy_config(self.cfg, self.meta["config"])
        self.params = jax.tree_util.tree_map(jnp.asarray, params)
        self._mean = jnp.asarray(self.pose_stats.mean, jnp.float32)
        self._std = jnp.asarray(self.pose_stats.std, jnp.float32)
        self._in_scale = input_scale(self.cfg, self._mean, self._std)  # inputs: one std per group
        self._fns = _jitted(self.cfg)

    def _encode_style(self, params, style, mask):
        """Style posterior of ``(b, S, P)`` clips; lengths padded (masked) to a bucket: few compilations."""
        S = style.shape[1]
        L = bucket_length(S)
        style = jnp.pad(jnp.asarray(style), ((0, 0), (0, L - S), (0, 0)))
        mask = jnp.pad(jnp.asarray(mask, bool), ((0, 0), (0, L - S)))
        return self._fns["encode_style"](params, style, mask)

    def _encode_speech(self, params, speech):
        return self._fns["encode_speech"](params, speech)

    def _generate(self, params, s_emb, e, y0, r0, q0, f, mean, std, weight_format: str = "fp32"):
        """The generator over ``s_emb (b, F, D_S)``; F padded to a bucket (the generator is causal: frames
        after F do not change frames before it) and the output cut back to F frames. ``weight_format``
        ``bf16`` / ``int8``: the decoder's kernels in that format (:mod:`jaxgest.zeggs.quant`)."""
        F = s_emb.shape[1]
        L = bucket_length(F)
        s_emb = jnp.pad(s_emb, ((0, 0), (0, L - F), (0, 0)))
        if weight_format != "fp32":
            from jaxgest.zeggs import quant

            quant.check_format(weight_format)
            cache = self.__dict__.setdefault("_quantized", {})
            if weight_format not in cache:
                cache[weight_format] = quant.quantize_params(params, weight_format)
            params = cache[weight_format]
            out = _quant_generate(self.cfg)(params, s_emb, e, y0, r0, q0, f, mean, std)
            return {k: v[:, :F] for k, v in out.items()}
        out = self._fns["generate"](params, s_emb, e, y0, r0, q0, f, mean, std)
        return {k: v[:, :F] for k, v in out.items()}

    # -- pieces ------------------------------------------------------------------------------------------
    def style_features(self, style: Motion) -> np.ndarray:
        """Pose features ``(F, P)`` of a style clip on the training rig at the model rate, normalised as the
        style encoder's input (per-channel mean, one std per group: ``cfg.input_norm``)."""
        return (self.pose_features(style) * np.asarray(self._in_scale)[None]).astype(np.float32)

    def pose_features(self, style: Motion) -> np.ndarray:
        """Pose features ``(F, P)`` of a clip on the training rig at the model rate, normalised per channel
        (the generator's output normalisation, in which it takes its initial pose)."""
        try:
            m = resample_motion(to_rig(style, self.reference), self.cfg.fps)
        except JaxgestError as e:  # e.g. a rig that matches no joint map: name the clip
            raise type(e)(f"{style.name or 'style clip'}: {e}") from None
        if m.num_frames < max(self.cfg.style_min_frames, int(MIN_STYLE_SECONDS * self.cfg.fps)):
            raise DataError(f"{style.name or 'style clip'}: {style.duration:.2f} s is too short for a style "
                            f"example (at least {MIN_STYLE_SECONDS} s)")
        return self.pose_stats.normalize(Fe.extract_features(m)["features"]).astype(np.float32)

    def style_posterior(self, style: Motion):
        """``(mu, logvar)`` each ``(D_e,)`` of one style clip."""
        x = self.style_features(style)
        mu, logvar = self._encode_style(self.params, jnp.asarray(x)[None], jnp.ones((1, len(x)), bool))
        return np.asarray(mu[0]), np.asarray(logvar[0])

    def style_embedding(self, styles: Sequence[Motion], *, weights=None, seed: int = 0, temperature: float = 1.0,
                        pca_edits: Optional[dict] = None, normalize_weights: bool = False) -> np.ndarray:
        """The blended (``sum_i w_i e_i``; PCA-edited) style embedding ``(D_e,)``."""
        if not styles:
            raise JaxgestError("at least one style clip is needed")
        w = validate_weights(weights, len(styles), normalize=normalize_weights)
        if not np.isfinite(temperature) or temperature < 0:
            raise JaxgestError(f"temperature must be finite and >= 0, got {temperature}")
        key = jax.random.PRNGKey(seed)
        es = []
        for i, s in enumerate(styles):
            mu, logvar = self.style_posterior(s)
            e = sample_style(jnp.asarray(mu)[None], jnp.asarray(logvar)[None], jax.random.fold_in(key, i),
                             float(temperature))
            es.append(np.asarray(e[0], np.float64))
        e = np.tensordot(w, np.stack(es), axes=1)
        if pca_edits:
            from jaxgest.zeggs.pca import StylePCA

            e = StylePCA.load(self.workdir / "pca.json").edit(e, pca_edits)
        return e.astype(np.float32)

    def speech(self, audio, sr: Optional[int] = None) -> tuple[np.ndarray, float]:
        """Normalised speech features ``(F, 81)`` at the model rate and the audio duration (s)."""
        from jaxgest.audio import load_audio, speech_features

        if isinstance(audio, (str, pathlib.Path)):
            y, sr = load_audio(audio)
        else:
            y = np.asarray(audio, np.float32)
            if sr is None:
                raise JaxgestError("an audio array needs its sample rate")
        duration = len(y) / float(sr)
        feats = speech_features(y, sr=sr, fps=self.cfg.fps, loudness=self.cfg.loudness)
        if len(feats) < 2:
            raise DataError(f"{audio if isinstance(audio, (str, pathlib.Path)) else 'audio'}: "
                            f"{duration:.3f} s of audio is too short to generate from")
        return self.speech_stats.normalize(feats).astype(np.float32), duration

    # -- generation --------------------------------------------------------------------------------------
    def generate(self, audio, styles: Sequence[Motion], *, weights=None, seed: int = 0, temperature: float = 1.0,
                 pca_edits: Optional[dict] = None, sr: Optional[int] = None, name: str = "generated",
                 normalize_weights: bool = False, weight_format: str = "fp32") -> Motion:
        """Gestures for ``audio`` in the (blended) style of ``styles``; a Motion on ``styles[0]``'s rig.

        ``weight_format``: ``fp32`` (default), ``bf16`` or ``int8`` generator weights (not the blend
        ``weights``; see :mod:`jaxgest.zeggs.quant`)."""
        if weight_format not in ("fp32", "bf16", "int8"):
            raise JaxgestError(f"weight format must be fp32, bf16 or int8, got {weight_format!r}")
        styles = list(styles)
        e = self.style_embedding(styles, weights=weights, seed=seed, temperature=temperature, pca_edits=pca_edits,
                                 normalize_weights=normalize_weights)
        speech, duration = self.speech(audio, sr=sr)
        first = self.pose_features(styles[0])
        F = speech.shape[0]
        s_emb = self._encode_speech(self.params, jnp.asarray(speech)[None])
        q0 = jnp.asarray([[1.0, 0.0, 0.0, 0.0]], jnp.float32)
        out = self._generate(self.params, s_emb, jnp.asarray(e)[None], jnp.asarray(first[:1]),
                             jnp.zeros((1, 3), jnp.float32), q0, jnp.asarray([[0.0, 0.0, 1.0]], jnp.float32),
                             self._mean, self._std, weight_format=weight_format)
        pose = self.pose_stats.denormalize(np.asarray(out["pose"][0], np.float64))
        root_p = np.asarray(out["root_position"][0], np.float64)
        root_q = np.asarray(out["root_rotation"][0], np.float64)
        template = self.reference.replace(rotations=np.repeat(self.reference.rotations[:1], F, 0),
                                          translations=np.repeat(self.reference.translations[:1], F, 0),
                                          fps=self.cfg.fps)
        motion = Fe.features_to_motion(pose, template, root_p, root_q, fps=self.cfg.fps, name=name)
        target = styles[0]
        if target.skeleton.names != motion.skeleton.names:
            body = B.retarget_to_body(motion)
            tmpl = target.replace(rotations=target.rotations[:1], translations=target.translations[:1])
            motion = B.retarget_from_body(body, tmpl).replace(name=name)
        out_frames = max(1, int(round(duration * target.fps)))
        motion = resample_motion(motion, target.fps)
        return fit_frames(motion, out_frames)


def bucket_length(n: int, smallest: int = 64) -> int:
    """The smallest of 64, 96, 128, 192, 256, 384, ... (2^k and 1.5 * 2^k) that is >= ``n``: sequence
    lengths padded to these share a compilation (at most 1.5x the frames)."""
    L = smallest
    while L < n:
        L = L * 3 // 2 if (L & (L - 1)) == 0 else L * 4 // 3
    return L


@functools.lru_cache(maxsize=8)
def _jitted(cfg) -> dict:
    """The jitted inference functions of a config (shared by every workdir with that config)."""
    model = ZeggsModel(cfg)
    opts = cfg.compiler_options
    return {
        "encode_style": jax.jit(lambda p, s, m: model.apply({"params": p}, s, m, method=ZeggsModel.encode_style),
                                compiler_options=opts),
        "encode_speech": jax.jit(lambda p, s: model.apply({"params": p}, s, method=ZeggsModel.encode_speech),
                                 compiler_options=opts),
        "generate": jax.jit(lambda p, s, e, y0, r0, q0, f, mean, std: model.apply(
            {"params": p}, s, e, y0, r0, q0, f, mean, std, method=ZeggsModel.generate), compiler_options=opts),
    }


@functools.lru_cache(maxsize=8)
def _quant_generate(cfg):
    """The jitted generator on quantised decoder weights (:func:`jaxgest.zeggs.quant.make_generate`)."""
    from jaxgest.zeggs import quant

    return jax.jit(quant.make_generate(cfg), compiler_options=cfg.compiler_options)


@functools.lru_cache(maxsize=4)
def _cached(workdir: str, mtime: float) -> ZeggsModel_:
    return ZeggsModel_(workdir)


def load_model(workdir) -> ZeggsModel_:
    """Load (and cache per workdir and checkpoint time) a trained ZeroEGGS model."""
    workdir = pathlib.Path(workdir).resolve()
    marker = workdir / "config.json"
    return _cached(str(workdir), marker.stat().st_mtime if marker.exists() else 0.0)


def generate(audio, styles, *, workdir, weights=None, seed: int = 0, temperature: float = 1.0,
             pca_edits: Optional[dict] = None, normalize_weights: bool = False,
             weight_format: str = "fp32") -> Motion:
    """SPEC §7: ``generate(audio, styles, *, workdir, weights=None, seed=0, temperature=1.0) -> Motion``."""
    if isinstance(styles, Motion):
        styles = [styles]
    return load_model(workdir).generate(audio, styles, weights=weights, seed=seed, temperature=temperature,
                                        pca_edits=pca_edits, normalize_weights=normalize_weights,
                                        weight_format=weight_format)
