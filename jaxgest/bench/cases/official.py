"""The ZeroEGGS authors' own PyTorch decoder beside jaxgest's run of the same network (same weights, same inputs).

* ``official_decode_b{1,32}``: the decoder rollout of an imported release (:func:`jaxgest.zeggs.official.
  network.decoder`: the cell-state encoder, then one ``lax.scan`` over the frames) generating ``frames``
  frames (300 = 5 s at 60 fps; 60 in ``--quick``) at the release's size (75 joints, pose input 1134, GRU
  2 x 1024, speech and style 64), ``jit`` vs ``authors``: their ``modules.Decoder.forward`` (a Python loop
  of eager PyTorch per frame, exactly as their ``generate.py`` calls it) with the same random weights
  (their classes' initialisation, seed 0), timed with every core's threads and with one thread as the
  other peers. Output compared: the root position and the local joint positions of every frame.

The authors' code is not part of jaxgest (CC BY-NC-ND): the cases run when ``JAXGEST_ZEGGS_CODE`` names
their ``ZEGGS/`` folder, or ``../shared/third_party/zeggs-official/ZEGGS`` exists beside the working
directory, and torch is installed; otherwise the module registers no case and says why.

Work per call: 2 FLOPs per decoder weight, batch row and frame; bytes = the decoder's fp32 weights per
frame (they do not stay in any cache between frames), as ``peer_zeggs_generate``.
References: Ghorbani et al. 2023, §3.3; the authors' ``modules.py``.
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
import os
import pathlib

import jax
import jax.numpy as jnp
import numpy as np

from jaxgest.bench.harness import Case, Impl
from jaxgest.zeggs.authors_path import their_code_on_path
from jaxgest.zeggs.official import network, quat

JOINTS, SPEECH, STYLE, HIDDEN = 75, 64, 64, 1024
P_IN, P_OUT = 9 + 15 * JOINTS, 6 + 15 * JOINTS
DT = 1.0 / 60.0


def code_dir() -> pathlib.Path | None:
    """Their ``ZEGGS/`` folder, if this machine has it (module doc)."""
    env = os.environ.get("JAXGEST_ZEGGS_CODE")
    path = pathlib.Path(env) if env else pathlib.Path.cwd().parent / "shared" / "third_party" / "zeggs-official" / "ZEGGS"
    return path if (path / "modules.py").is_file() else None


def missing_reason() -> str | None:
    if importlib.util.find_spec("torch") is None:
        return "torch is not installed"
    if code_dir() is None:
        return "the authors' ZEGGS/ code is not found (set JAXGEST_ZEGGS_CODE)"
    return None


@functools.lru_cache(maxsize=None)
def _their_modules():
    """Their ``modules.py``, imported with their folder on the path only meanwhile (nothing left behind)."""
    with their_code_on_path(code_dir()):
        return importlib.import_module("modules")


@functools.lru_cache(maxsize=None)
def _decoder():
    """Their ``Decoder`` at the release's size, seed 0 (eval mode), and its weights as jaxgest params."""
    import torch

    torch.manual_seed(0)
    dec = _their_modules().Decoder(pose_input_size=P_IN, pose_output_size=P_OUT, speech_encoding_size=SPEECH,
                                   style_encoding_size=STYLE, hidden_size=HIDDEN, num_rnn_layers=2).eval()
    params = {k: jnp.asarray(v.detach().numpy()) for k, v in dec.state_dict().items()}
    return dec, params


def _inputs(batch: int, frames: int, seed: int = 0) -> tuple:
    """A valid pose state, a gaze target, speech and style encodings, and unit statistics scaled to the
    release's magnitudes (positions tens of cm)."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(batch, JOINTS, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    yaw = rng.uniform(-np.pi, np.pi, size=batch)
    root_rot = np.stack([np.cos(yaw / 2), 0 * yaw, np.sin(yaw / 2), 0 * yaw], -1)
    state = {"root_pos": rng.normal(scale=10.0, size=(batch, 3)) * [1, 0, 1], "root_rot": root_rot,
             "root_vel": rng.normal(size=(batch, 3)), "root_vrt": rng.normal(scale=0.1, size=(batch, 3)),
             "lpos": rng.normal(scale=10.0, size=(batch, JOINTS, 3)), "ltxy": quat.two_axis(q),
             "lvel": rng.normal(size=(batch, JOINTS, 3)), "lvrt": rng.normal(size=(batch, JOINTS, 3))}
    state = {k: np.asarray(v, np.float32) for k, v in state.items()}
    gaze = np.repeat(np.asarray(rng.normal(scale=100.0, size=(batch, 1, 3)) * [1, 0, 1], np.float32), frames, 1)
    speech = np.asarray(rng.normal(scale=0.5, size=(batch, frames, SPEECH)), np.float32)
    style = np.repeat(np.asarray(rng.normal(size=(batch, 1, STYLE)), np.float32), frames, 1)
    stats = {"anim_input_mean": np.zeros(P_IN, np.float32), "anim_input_std": np.full(P_IN, 10.0, np.float32),
             "anim_output_mean": np.zeros(P_OUT, np.float32), "anim_output_std": np.full(P_OUT, 0.1, np.float32)}
    return state, gaze, speech, style, stats


def _jit_fn():
    decode = jax.jit(functools.partial(network.decoder, dt=DT, cond="normal"))

    def run(params, state, gaze, speech, style, stats):
        out = decode(params, state, gaze, speech, style, stats)
        return jnp.concatenate([out["root_pos"], out["lpos"].reshape(out["lpos"].shape[:2] + (-1,))], axis=-1)

    return run


def _authors_fn(threads: int):
    def run(params, state, gaze, speech, style, stats):
        import torch

        torch.set_num_threads(threads)
        dec, _ = _decoder()
        t = {k: torch.as_tensor(np.asarray(v)) for k, v in state.items()}
        s = {k: torch.as_tensor(np.asarray(v)) for k, v in stats.items()}
        with torch.no_grad():
            out = dec(t["root_pos"], t["root_rot"], t["root_vel"], t["root_vrt"], t["lpos"], t["ltxy"], t["lvel"],
                      t["lvrt"], torch.as_tensor(np.asarray(gaze)), torch.as_tensor(np.asarray(speech)),
                      torch.as_tensor(np.asarray(style)), torch.zeros(JOINTS, dtype=torch.long),
                      s["anim_input_mean"], s["anim_input_std"], s["anim_output_mean"], s["anim_output_std"], DT)
        root_pos, lpos = out[0], out[4]
        return torch.cat([root_pos, lpos.reshape(lpos.shape[:2] + (-1,))], dim=-1).numpy()

    return run


def official_case(batch: int, frames: int) -> Case:
    from jaxgest.bench.cases.peers import threads, torch_threads

    impls = [Impl("jit", _jit_fn(), kind="jit")]
    impls += [Impl("authors" if name == "torch" else name.replace("torch", "authors"), _authors_fn(n))
              for name, n in torch_threads()]
    n_weights = sum(int(np.prod(v.shape)) for k, v in _decoder()[1].items()
                    if k.startswith("recurrent_decoder") and "weight" in k)

    def work(impl):
        return 2.0 * batch * n_weights * frames, 4.0 * n_weights * frames

    return Case(
        name=f"official_decode_b{batch}", batch=batch, frames=frames, impls=impls,
        make_args=lambda: (_decoder()[1],) + _inputs(batch, frames), rtol=1e-3, atol=1e-2, interleave=True,
        work=work,
        note=f"the authors' Decoder (modules.py, their code, eager) vs jaxgest.zeggs.official, same random weights; "
             f"{frames} generated frames; torch threads {threads()}",
    )


def cases(quick: bool) -> list:
    reason = missing_reason()
    if reason:
        print(f"bench: official_decode cases skipped: {reason}")
        return []
    frames = 60 if quick else 300
    return [official_case(1, frames), official_case(32, frames if not quick else 30)]
