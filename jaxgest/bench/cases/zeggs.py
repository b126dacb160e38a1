"""ZeroEGGS cases: generation per frame (batch 1 and 32), style encoder per clip, speech encoder and
speech features per second of audio.

Weights: the ``paper`` preset (25.5 M parameters, 75-joint pose of 1131 channels, GRU 2 x 1024) with
fixed random weights (:func:`random_params`: LeCun-normal kernels, zero biases, unit LayerNorm scales --
the distribution of flax's initialisers without compiling ``init``, which costs ~10 s; speed does not
depend on the values). Inputs are random speech embeddings / pose features / a unit style embedding.

* ``zeggs_generate_check_b{1,32}``: the generator on a short sequence (8 generated frames), ``jit`` vs
  eager JAX (``jax.disable_jit``: flax's scan runs as a Python loop of op-by-op calls) vs the NumPy
  reference (:mod:`jaxgest.bench.numpy_zeggs`) -- the equality check of the generator.
* ``zeggs_generate_b1`` / ``zeggs_generate_b32``: :meth:`ZeggsModel.generate` (hidden-state initializer +
  one ``nn.scan`` over the frames) generating ``frames`` frames (300 = 5 s at 60 fps; 60 in ``--quick``)
  after warm-up, ``jit`` (and NumPy at batch 1 in the full run). ``per_pose_us`` is per generated frame
  and sequence; the per-frame latency of the batch is ``per_frame_us`` (= per pose x batch).
* ``zeggs_style_encoder_b{1,32}``: posterior of a 512-frame style clip (the longest training window),
  ``jit`` vs eager. Per pose = per style frame.
* ``zeggs_speech_encoder_b1``: speech encoder on 10 s (600 frames), ``jit`` vs eager.
* ``zeggs_speech_features``: :func:`jaxgest.audio.speech_features` ``method="librosa"`` (librosa STFT + mel,
  NumPy only; the method of models trained before the authors' one) on 10 s of 16 kHz speech-like audio;
  frames = 600 output frames at 60 fps, ``per_frame_us`` x 60 = cost per second of audio.
  ``zeggs_speech_features_authors``: the same with ``method="authors"`` (the default of new models).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.bench import numpy_zeggs
from jaxgest.bench.harness import Case, Impl
from jaxgest.zeggs.config import ModelConfig, preset
from jaxgest.zeggs.model import ZeggsModel, init_params

CFG = preset("paper").model
STYLE_FRAMES = 512
AUDIO_SECONDS = 10.0
AUDIO_SR = 16000
CHECK_FRAMES = 8  # generated frames of the equality-check cases (eager JAX is ~15x slower than jit)


def random_params(cfg: ModelConfig, seed: int = 0) -> dict:
    """Parameters shaped as ``init_params(cfg)``: LeCun-normal kernels, zero biases, unit LayerNorm scales."""
    shapes = jax.eval_shape(lambda k: init_params(cfg, k), jax.random.key(0))
    rng = np.random.default_rng(seed)

    def fill(path, leaf):
        name = jax.tree_util.keystr(path[-1:])
        if "kernel" in name:
            fan_in = int(np.prod(leaf.shape[:-1]))
            return jnp.asarray(rng.normal(scale=1.0 / np.sqrt(fan_in), size=leaf.shape), jnp.float32)
        if "scale" in name:
            return jnp.ones(leaf.shape, jnp.float32)
        return jnp.zeros(leaf.shape, jnp.float32)

    return jax.tree_util.tree_map_with_path(fill, shapes)


@functools.lru_cache(maxsize=None)
def _params(name: str = "paper"):
    return random_params(preset(name).model)


def generator_inputs(cfg: ModelConfig, batch: int, frames: int, seed: int = 0) -> tuple:
    """``(speech_embedding (b, frames + 1, D_S), style (b, D_e), pose0, root_position0, root_rotation0,
    facing)``: ``frames`` frames are generated after the given frame 0."""
    rng = np.random.default_rng(seed * 7919 + batch * 31 + frames)
    f32 = lambda a: jnp.asarray(a, jnp.float32)  # noqa: E731
    speech = f32(rng.uniform(0.0, 1.0, size=(batch, frames + 1, cfg.speech_embedding)))
    style = f32(rng.normal(size=(batch, cfg.style_embedding)) / np.sqrt(cfg.style_embedding))
    pose0 = f32(rng.normal(scale=0.5, size=(batch, cfg.pose_dim)))
    q0 = np.zeros((batch, 4))
    q0[:, 0] = 1.0
    facing = np.zeros((batch, 3))
    facing[:, 2] = 1.0
    return speech, style, pose0, f32(np.zeros((batch, 3))), f32(q0), f32(facing)


def _generate_fn(cfg: ModelConfig):
    model = ZeggsModel(cfg)

    def generate(params, speech, style, pose0, root_position0, root_rotation0, facing):
        return model.apply({"params": params}, speech, style, pose0, root_position0, root_rotation0, facing,
                           method=ZeggsModel.generate)

    return generate


def _eager(f):
    def run(*args):
        with jax.disable_jit():
            return f(*args)

    return run


def _numpy_generate(cfg: ModelConfig):
    lay = cfg.layout

    def run(params, *inputs):
        return numpy_zeggs.generate(params["generator"], *inputs, fps=cfg.fps,
                                    root_velocity=lay.root_velocity,
                                    root_angular_velocity=lay.root_angular_velocity)

    return run


def generate_case(batch: int, frames: int, *, name: str, with_eager: bool = False, with_numpy: bool = True,
                  quick: bool = True) -> Case:
    f = _generate_fn(CFG)
    impls = [Impl("jit", jax.jit(f), kind="jit")]
    if with_eager:
        impls.append(Impl("eager", _eager(f)))
    if with_numpy:
        impls.append(Impl("numpy", _numpy_generate(CFG)))
    return Case(
        name=name, batch=batch, frames=frames, impls=impls,
        make_args=lambda: (_params(),) + generator_inputs(CFG, batch, frames),
        rtol=1e-3, atol=1e-3, quick=quick,
        note=f"paper preset (GRU 2x{CFG.gru_hidden}, pose {CFG.pose_dim}), random weights; {frames} "
             f"generated frames after frame 0; per pose = per generated frame and sequence",
    )


def _style_fn(cfg: ModelConfig):
    model = ZeggsModel(cfg)

    def encode_style(params, style, mask):
        return model.apply({"params": params}, style, mask, method=ZeggsModel.encode_style)

    return encode_style


def style_case(batch: int, frames: int = STYLE_FRAMES, *, quick: bool = True) -> Case:
    f = _style_fn(CFG)

    def make_args():
        rng = np.random.default_rng(batch * 13 + frames)
        x = jnp.asarray(rng.normal(size=(batch, frames, CFG.pose_dim)), jnp.float32)
        return _params(), x, jnp.ones((batch, frames), bool)

    return Case(name=f"zeggs_style_encoder_b{batch}", batch=batch, frames=frames,
                impls=[Impl("jit", jax.jit(f), kind="jit"), Impl("eager", _eager(f))], make_args=make_args,
                rtol=1e-3, atol=1e-3, quick=quick,
                note=f"paper preset style encoder (conv {CFG.style_hidden}, FFT block), {frames}-frame clip; "
                     "per pose = per style frame")


def _speech_fn(cfg: ModelConfig):
    model = ZeggsModel(cfg)

    def encode_speech(params, speech):
        return model.apply({"params": params}, speech, method=ZeggsModel.encode_speech)

    return encode_speech


def speech_encoder_case(batch: int = 1, seconds: float = AUDIO_SECONDS) -> Case:
    frames = int(round(seconds * CFG.fps))
    f = _speech_fn(CFG)

    def make_args():
        x = np.random.default_rng(frames).normal(size=(batch, frames, CFG.speech_dim))
        return _params(), jnp.asarray(x, jnp.float32)

    return Case(name=f"zeggs_speech_encoder_b{batch}", batch=batch, frames=frames,
                impls=[Impl("jit", jax.jit(f), kind="jit"), Impl("eager", _eager(f))], make_args=make_args,
                rtol=1e-3, atol=1e-3, note=f"{seconds:g} s of speech features at {CFG.fps:g} fps")


def speech_like_audio(seconds: float, sr: int = AUDIO_SR, seed: int = 0) -> np.ndarray:
    """Voiced bursts (harmonics of a gliding pitch under a syllable-rate envelope) plus a little noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * sr)) / sr
    f0 = 120.0 + 30.0 * np.sin(2 * np.pi * 0.7 * t)
    phase = 2 * np.pi * np.cumsum(f0) / sr
    voiced = sum(np.sin(k * phase) / k for k in range(1, 8))
    envelope = np.clip(np.sin(2 * np.pi * 4.0 * t), 0.0, None) ** 2
    return (0.3 * envelope * voiced + 0.01 * rng.normal(size=t.shape)).astype(np.float32)


def speech_features_case(seconds: float = AUDIO_SECONDS, method: str = "librosa") -> Case:
    from jaxgest.audio import speech_features

    frames = int(round(seconds * CFG.fps))
    return Case(name="zeggs_speech_features" + ("" if method == "librosa" else f"_{method}"), batch=1,
                frames=frames,
                impls=[Impl("numpy", lambda y: speech_features(y, sr=AUDIO_SR, fps=CFG.fps, method=method))],
                make_args=lambda: (speech_like_audio(seconds),),
                note=f"jaxgest.audio.speech_features ({method}) on {seconds:g} s of {AUDIO_SR} Hz audio -> "
                     f"{frames} frames; per second of audio = per_frame_us x {CFG.fps:g}")


def cases(quick: bool) -> list:
    # --quick: the generator's per-frame cost at 60 frames (it does not depend on the length: one scan),
    # jit only; the full run: 300 frames, jit vs NumPy at batch 1. At batch 32 NumPy is compared on the
    # check case only: OpenBLAS threads spinning on a loaded machine made it minutes per 300-frame call.
    frames = 60 if quick else 300
    return [
        generate_case(1, CHECK_FRAMES, name="zeggs_generate_check_b1", with_eager=True),
        generate_case(32, CHECK_FRAMES, name="zeggs_generate_check_b32", with_eager=True, quick=False),
        generate_case(1, frames, name="zeggs_generate_b1", with_numpy=not quick),
        generate_case(32, frames, name="zeggs_generate_b32", with_numpy=False),
        style_case(1),
        style_case(32, quick=False),
        speech_encoder_case(),
        speech_features_case(),
        speech_features_case(method="authors"),
    ]
