"""Generation with an imported release of the ZeroEGGS authors' models, as their ``generate_gesture``.

``OfficialZeggs.generate(audio, styles, *, weights=None, seed=0, temperature=None, first_pose=None)``:

1. speech: the authors' features (:func:`jaxgest.audio.speech_features` with ``method="authors"``: 16 kHz,
   -20 LUFS, their mel + energy), ``round(60 * duration)`` frames, normalised with the release's
   ``audio_input_mean`` / ``audio_input_std``, through the speech encoder;
2. style: example-based models (v1) encode each example clip (ZEGGS rig; resampled to 60 fps if needed) --
   its ``[root_vel, root_vrt, lpos, ltxy, lvel, lvrt, 0, 0, 0]`` vector (zeros in the gaze slot, as theirs),
   normalised with ``anim_input_mean/std`` -- to ``(mu, logvar)`` and samples ``e = mu + temperature * sigma
   * eps`` (jaxgest's convention: temperature 0 is the posterior mean; the authors divide sigma by their
   temperature, so theirs at a very large value is ours at 0). Label-based models (v2) take label names and
   use their one-hot vectors. Several styles are blended as ``e = sum_i w_i e_i`` (their ``"add"`` blend);
3. the initial pose state is frame 0 of ``first_pose``, or of the **last** example clip when none is given
   (theirs); the gaze target is that clip's (fixed for the whole output, as theirs);
4. the decoder runs ``T - 1`` steps (:func:`jaxgest.zeggs.official.network.decoder`); the output is put on
   the ZEGGS rig as their ``utils.write_bvh`` writes it: the root starts at the origin facing +Z, every
   joint's offset is the predicted local position of frame 0. 60 fps.

References: the authors' ``generate.py`` (``generate_gesture``) and ``utils.write_bvh``; Ghorbani et al.
2023, §3 (inference from an example clip), §5.2.1 (blending).
"""

from __future__ import annotations

import dataclasses
import functools
import os
import pathlib
from typing import Optional

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.motion import bvh
from jaxgest.motion.datasets import resample_motion
from jaxgest.motion.skeleton import Motion
from jaxgest.runtime.errors import DataError, JaxgestError
from jaxgest.zeggs.official import features, network, quat
from jaxgest.zeggs.official.release import Release, read_workdir


def _bucket(n: int) -> int:
    from jaxgest.zeggs.inputs import bucket_length

    return bucket_length(n)


class OfficialZeggs:
    """An imported release (``jaxgest zeggs import-official``) with jitted networks; see the module doc.

    Attributes: ``release`` (manifest, params, stats), ``fps`` (60), ``label_names``, ``example_based``.
    """

    def __init__(self, release: Release, workdir=None):
        self.release = release
        self.workdir = pathlib.Path(workdir) if workdir is not None else None
        m = release.manifest
        self.fps = float(m["fps"])
        self.dt = float(m["dt"])
        self.label_names = list(m["label_names"])
        self.bone_names = tuple(m["bone_names"])
        self.example_based = release.example_based
        self.joints = dict(m.get("root_joints", features.ZEGGS_JOINTS))
        self.params = {k: {n: jnp.asarray(a) for n, a in v.items()} for k, v in release.params.items()}
        self.stats = {k: jnp.asarray(v) for k, v in release.stats.items()}
        self._speech = jax.jit(network.speech_encoder)
        self._style = jax.jit(network.style_encoder)
        self._decoder = jax.jit(functools.partial(network.decoder, dt=self.dt, cond=m["rnn_cond"]))

    @classmethod
    def load(cls, workdir) -> "OfficialZeggs":
        return cls(read_workdir(workdir), workdir)

    # -- pieces ------------------------------------------------------------------------------------------
    def clip(self, motion: Motion) -> Motion:
        """``motion`` checked to be on the model's rig and at its frame rate (resampled when it is not)."""
        name = motion.name or "clip"
        if tuple(motion.skeleton.names) != self.bone_names:
            raise DataError(f"{name}: the authors' model needs a clip of its own rig ({len(self.bone_names)} "
                            f"ZEGGS joints); this one has {motion.skeleton.num_joints} joints"
                            + ("" if motion.skeleton.num_joints != len(self.bone_names) else " in another order"))
        if abs(motion.fps - self.fps) > 0.01:  # frame times are written rounded (0.0166667 s)
            motion = resample_motion(motion, self.fps)
        return motion

    def speech(self, audio, sr: Optional[int] = None) -> np.ndarray:
        """Normalised speech features ``(T, 81)`` of a path or samples (the authors' features)."""
        from jaxgest.audio import load_audio, speech_features

        if isinstance(audio, (str, os.PathLike)):
            y, sr = load_audio(audio)
            name = str(audio)
        else:
            y, name = np.asarray(audio, np.float32), "audio"
            if sr is None:
                raise JaxgestError("an audio array needs its sample rate")
        feats = speech_features(y, sr=sr, fps=self.fps, method="authors")
        if len(feats) < 2:
            raise DataError(f"{name}: {len(y) / float(sr):.3f} s of audio is too short to generate from")
        s = self.release.stats
        return ((feats - s["audio_input_mean"]) / s["audio_input_std"]).astype(np.float32)

    def style_input(self, motion: Motion) -> np.ndarray:
        """The style encoder's normalised input ``(F, 9 + 15 J)`` of an example clip (gaze slot zero)."""
        vec = features.pose_vector(features.pose_state(self.clip(motion), self.joints), gaze=False)
        vec = np.concatenate([vec, np.zeros((len(vec), 3))], axis=1)
        s = self.release.stats
        return ((vec - s["anim_input_mean"]) / s["anim_input_std"]).astype(np.float32)

    def style_posterior(self, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
        """``(mu, logvar)`` each ``(D_e,)`` of one example clip."""
        if not self.example_based:
            raise JaxgestError("this model is label-based (v2): it has no style encoder; give a label "
                               f"({', '.join(self.label_names)})")
        mu, logvar = self._style(self.params["style_encoder"], jnp.asarray(self.style_input(motion))[None])
        return np.asarray(mu[0]), np.asarray(logvar[0])

    def style_embeddings(self, styles, *, seed: int = 0, temperature: float = 1.0) -> list[np.ndarray]:
        """One embedding per style: sampled from each example's posterior, or a label's one-hot vector."""
        out = []
        key = jax.random.key(seed)
        for i, s in enumerate(styles):
            if self.example_based:
                mu, logvar = self.style_posterior(s)
                eps = np.asarray(jax.random.normal(jax.random.fold_in(key, i), mu.shape), np.float64)
                out.append(mu + float(temperature) * np.exp(0.5 * logvar) * eps)
            else:
                one_hot = np.zeros(len(self.label_names))
                one_hot[self.label_names.index(s)] = 1.0
                out.append(one_hot)
        return out

    def _styles(self, styles) -> list:
        if isinstance(styles, (Motion, str, os.PathLike)):
            styles = [styles]
        styles = list(styles)
        if not styles:
            raise JaxgestError("at least one style is needed")
        if self.example_based:
            return [bvh.as_motion(s, "style") for s in styles]
        bad = [s for s in styles if not isinstance(s, str) or s not in self.label_names]
        if bad:
            raise JaxgestError(f"this model is label-based (v2): styles must be among {', '.join(self.label_names)}"
                               f"; got {', '.join(map(str, bad))}")
        return styles

    # -- generation --------------------------------------------------------------------------------------
    def generate(self, audio, styles, *, weights=None, seed: int = 0, temperature: Optional[float] = None,
                 first_pose=None, sr: Optional[int] = None, name: str = "generated",
                 normalize_weights: bool = False, pca_edits: Optional[dict] = None,
                 weight_format: str = "fp32") -> Motion:
        """Gestures for ``audio`` in the (blended) style of ``styles`` on the ZEGGS rig at 60 fps (module doc)."""
        from jaxgest.zeggs.inputs import audio_input, validate_weights

        if weight_format != "fp32":
            raise JaxgestError(f"an imported authors' model runs in fp32 only, got weight format {weight_format!r}")
        if pca_edits:
            raise JaxgestError("PCA edits are not available for an imported authors' model")
        temperature = 1.0 if temperature is None else float(temperature)
        if not np.isfinite(temperature) or temperature < 0:
            raise JaxgestError(f"temperature must be finite and >= 0, got {temperature}")
        styles = self._styles(styles)
        w = validate_weights(weights, len(styles), normalize=normalize_weights)
        if first_pose is not None:
            first = self.clip(bvh.as_motion(first_pose, "first pose"))
        elif self.example_based:
            first = self.clip(styles[-1])
        else:
            raise JaxgestError("a label-based model (v2) needs a first pose: --first-pose BVH (ZEGGS rig)")
        audio, sr = audio_input(audio, sr)
        e = np.tensordot(w, np.stack(self.style_embeddings(styles, seed=seed, temperature=temperature)), axes=1)
        speech = self.speech(audio, sr)
        state = features.pose_state(first, self.joints)
        return self.decode(speech, e, state, name=name, template=first)

    def decode(self, speech: np.ndarray, style: np.ndarray, state: dict, *, name: str, template: Motion) -> Motion:
        """Run the speech encoder and the decoder from frame 0 of ``state``; the result as a Motion."""
        T = len(speech)
        s_emb = self._speech(self.params["speech_encoder"], jnp.asarray(speech)[None])
        L = _bucket(T)  # the decoder is causal: padding frames after T changes nothing before T
        s_emb = jnp.pad(s_emb, ((0, 0), (0, L - T), (0, 0)))
        style_seq = jnp.broadcast_to(jnp.asarray(style, jnp.float32)[None, None], (1, L, len(style)))
        gaze = jnp.broadcast_to(jnp.asarray(state["gaze_pos"][0], jnp.float32)[None, None], (1, L, 3))
        state0 = {k: jnp.asarray(state[k][:1], jnp.float32) for k in network.STATE_KEYS}
        out = self._decoder(self.params["decoder"], state0, gaze, s_emb, style_seq, self.stats)
        out = {k: np.asarray(v[0, :T], np.float64) for k, v in out.items()}
        return to_motion(out, template, fps=self.fps, name=name)


def to_motion(out: dict, template: Motion, *, fps: float, name: str) -> Motion:
    """Decoder outputs ``{root_pos, root_rot, lpos, ltxy}`` ``(T, ...)`` as a Motion on ``template``'s rig,
    as the authors' ``utils.write_bvh`` with ``start_position=0``, ``start_rotation=identity``: the root
    re-based to start at the origin facing +Z, every non-root joint at its predicted frame-0 local position
    (the file's offsets). References: the authors' ``generate.py`` and ``utils.write_bvh``."""
    lrot = quat.from_two_axis(out["ltxy"])
    lpos = np.array(out["lpos"], np.float64)
    p0, q0 = out["root_pos"][0:1], out["root_rot"][0:1]
    root_pos = quat.mul_vec(quat.inv(q0), out["root_pos"] - p0)
    root_rot = quat.mul(quat.inv(q0), out["root_rot"])
    lpos[:, 0] = quat.mul_vec(root_rot, lpos[:, 0]) + root_pos
    lrot[:, 0] = quat.normalize(quat.mul(root_rot, lrot[:, 0]))
    T = len(lpos)
    translations = np.repeat(lpos[:1], T, axis=0)
    translations[:, 0] = lpos[:, 0]
    skeleton = dataclasses.replace(template.skeleton, offsets=lpos[0].copy())
    return Motion(skeleton=skeleton, rotations=lrot, translations=translations, fps=fps, name=name)


def load(workdir) -> OfficialZeggs:
    """The imported release of ``workdir``."""
    return OfficialZeggs.load(workdir)


__all__ = ["OfficialZeggs", "load", "to_motion"]

