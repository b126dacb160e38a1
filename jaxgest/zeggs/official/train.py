"""Train the ZeroEGGS authors' network on the authors' representation with the authors' objective, in JAX.

``jaxgest zeggs train --preset authors | authors-tiny`` (:func:`train`) trains what ``import-official``
imports: the networks of :mod:`jaxgest.zeggs.official.network` (their parameter names, PyTorch's default
initialisation, :func:`init_params`), the features of :mod:`~jaxgest.zeggs.official.features` (joint-local,
paper 001 §3.2-3.3), the 17 terms and KL schedule of :mod:`~jaxgest.zeggs.official.losses`, and their data
handling:

* every clip (with its speech) at 60 fps, mirrored, and at 0.9 of its length (their ``len_ratios``: motion
  and audio resampled together; the audio linearly here, cubic in theirs);
* statistics as their ``data_pipeline``: per-channel means, one std per feature group for the inputs and per
  channel for the outputs, over frames 2 .. n-2 of every sequence; audio mean per channel, one std;
* windows of ``window`` frames at uniformly drawn starts; a style example around each window (their
  ``get_example``) of ``2 * randint(L/2, L)`` frames, one length per step, ``L = example_length``;
* RAdam (lr 1e-4, eps 1e-5), the rate times 0.995 every 1000 steps (their ``ExponentialLR`` stepped every
  1000 iterations); dropout as their modules in training.

The batch of step ``i`` is a pure function of ``(seed, i)``, the step is one jitted function with the state
donated, checkpoints are orbax (:class:`jaxgest.runtime.checkpoint.Checkpointer`), so a killed run resumes
to the parameters of an uninterrupted one. At the end the workdir gets ``official.json`` and the weights, the
format ``import-official`` writes: ``zeggs generate`` and ``jaxgest.zeggs.load`` read it as a release.

References: Ghorbani et al. 2023, §4.1-4.3; the authors' ``train.py``, ``dataset.py`` (``SGDataset``),
``data_pipeline.py``, ``optimizers.py`` (RAdam); Liu et al. 2020 (RAdam).
"""

from __future__ import annotations

import copy
import dataclasses
import math
import pathlib
import time
from typing import Optional

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxgest.runtime.errors import DataError, JaxgestError

#: The presets: the release's options (v1, example-based) and a tiny one for tests and the smoke run.
PRESETS = {
    "authors": {
        "net_opt": {"decoder": {"nhidden": 1024, "num_rnn_layers": 2, "rnn_cond": "normal"},
                    "speech_encoder": {"nhidden": 64, "speech_encoding_size": 64},
                    "style_encoder": {"nhidden": 512, "style_encoding_size": 64, "example_length": 256,
                                      "type": "attn", "use_vae": True}},
        "train_opt": {"niterations": 160, "batchsize": 32, "window": 256, "learning_rate": 1e-4,
                      "learning_rate_decay": 0.995, "eps": 1e-5, "style_encoding_type": "example"},
    },
    "authors-tiny": {
        "net_opt": {"decoder": {"nhidden": 32, "num_rnn_layers": 2, "rnn_cond": "normal"},
                    "speech_encoder": {"nhidden": 16, "speech_encoding_size": 16},
                    "style_encoder": {"nhidden": 32, "style_encoding_size": 8, "example_length": 48,
                                      "type": "attn", "use_vae": True}},
        "train_opt": {"niterations": 0.02, "batchsize": 4, "window": 32, "learning_rate": 1e-3,
                      "learning_rate_decay": 0.995, "eps": 1e-5, "style_encoding_type": "example"},
    },
}
LEN_RATIOS = (0.9, 1.0)
FPS = 60.0
KIND = "zeggs_official"


def preset_steps(options: dict) -> int:
    """Their ``niterations`` is in thousands of iterations."""
    return int(round(1000 * float(options["train_opt"]["niterations"])))


# -- parameters ----------------------------------------------------------------------------------------
def param_shapes(options: dict, joints: int, speech_dim: int = 81) -> dict[str, dict[str, tuple]]:
    """Every parameter of the three networks under the authors' names (``state_dict()`` keys) and shapes."""
    net = options["net_opt"]
    S, Hs = int(net["speech_encoder"]["speech_encoding_size"]), int(net["speech_encoder"]["nhidden"])
    H, L = int(net["decoder"]["nhidden"]), int(net["decoder"]["num_rnn_layers"])
    E, Hst = int(net["style_encoder"]["style_encoding_size"]), int(net["style_encoder"]["nhidden"])
    P_in, P_out, D = 9 + 15 * joints, 6 + 15 * joints, 2 * E
    speech = {"layer0.weight": (Hs, speech_dim, 1), "layer0.bias": (Hs,), "layer1.weight": (S, Hs, 31),
              "layer1.bias": (S,), "layer2.weight": (S, S), "layer2.bias": (S,)}
    dec = {}
    for name, (o, i) in {"cell_state_encoder.layer0": (H, P_in + E), "cell_state_encoder.layer1": (H, H),
                         "cell_state_encoder.layer2": (H * L, H), "recurrent_decoder.layer0": (H, P_in + S + E),
                         "recurrent_decoder.layer2": (P_out, H)}.items():
        dec[f"{name}.weight"], dec[f"{name}.bias"] = (o, i), (o,)
    for layer in range(L):
        g = "recurrent_decoder.layer1"
        dec[f"{g}.weight_ih_l{layer}"] = (3 * H, (P_in + S + E + H) if layer == 0 else H)
        dec[f"{g}.weight_hh_l{layer}"] = (3 * H, H)
        dec[f"{g}.bias_ih_l{layer}"] = dec[f"{g}.bias_hh_l{layer}"] = (3 * H,)
    e, b = "encoder", "encoder.blocks.0"
    style = {f"{e}.convs.0.conv.weight": (Hst, P_in, 3), f"{e}.convs.0.conv.bias": (Hst,),
             f"{e}.convs.2.weight": (Hst,), f"{e}.convs.2.bias": (Hst,),
             f"{e}.convs.4.conv.weight": (D, Hst, 3), f"{e}.convs.4.conv.bias": (D,),
             f"{e}.convs.6.weight": (D,), f"{e}.convs.6.bias": (D,),
             f"{b}.attention.multi_head_attention.in_proj_weight": (3 * D, D),
             f"{b}.attention.multi_head_attention.in_proj_bias": (3 * D,),
             f"{b}.attention.multi_head_attention.out_proj.weight": (D, D),
             f"{b}.attention.multi_head_attention.out_proj.bias": (D,),
             f"{b}.attention.layer_norm.weight": (D,), f"{b}.attention.layer_norm.bias": (D,),
             f"{b}.feed_forward.convs.0.conv.weight": (D, D, 3), f"{b}.feed_forward.convs.0.conv.bias": (D,),
             f"{b}.feed_forward.convs.2.conv.weight": (D, D, 3), f"{b}.feed_forward.convs.2.conv.bias": (D,),
             f"{b}.feed_forward.layer_norm.weight": (D,), f"{b}.feed_forward.layer_norm.bias": (D,)}
    return {"speech_encoder": speech, "decoder": dec, "style_encoder": style}


def init_params(options: dict, joints: int, key: jax.Array) -> dict:
    """Parameters as PyTorch initialises the authors' modules: ``nn.Linear`` / ``nn.Conv1d`` / ``nn.GRU``
    uniform in ``+-1/sqrt(fan_in)`` (GRU: ``1/sqrt(H)``), LayerNorm ones and zeros, their ``ConvNorm1D``
    Xavier-uniform (gain ReLU, or linear for the last feed-forward conv) with PyTorch's default bias, the
    attention's input projection Xavier-uniform with zero biases. References: PyTorch's ``reset_parameters``
    of those layers; the authors' ``modules.py`` (``ConvNorm1D``, ``LinearNorm`` gains)."""
    shapes = param_shapes(options, joints)
    H = int(options["net_opt"]["decoder"]["nhidden"])
    out = {}
    for net, named in shapes.items():
        key, sub = jax.random.split(key)
        keys = dict(zip(named, jax.random.split(sub, len(named))))
        arrays = {}
        for name, shape in named.items():
            k = keys[name]
            if net == "style_encoder" and ("norm" in name or name.endswith(("convs.2.weight", "convs.2.bias",
                                                                             "convs.6.weight", "convs.6.bias"))):
                arrays[name] = jnp.ones(shape) if name.endswith("weight") else jnp.zeros(shape)
                continue
            if "in_proj" in name or "out_proj.bias" in name:
                if name.endswith("bias"):
                    arrays[name] = jnp.zeros(shape)
                else:
                    bound = math.sqrt(6.0 / (shape[0] + shape[1]))  # xavier_uniform_ of the (3D, D) matrix
                    arrays[name] = jax.random.uniform(k, shape, minval=-bound, maxval=bound)
                continue
            if net == "style_encoder" and ".conv.weight" in name:
                gain = 1.0 if "feed_forward.convs.2" in name else math.sqrt(2.0)
                fan_in, fan_out = shape[1] * shape[2], shape[0] * shape[2]
                bound = gain * math.sqrt(6.0 / (fan_in + fan_out))
                arrays[name] = jax.random.uniform(k, shape, minval=-bound, maxval=bound)
                continue
            if net == "decoder" and ("layer1.weight_" in name or "layer1.bias_" in name):  # nn.GRU
                bound = 1.0 / math.sqrt(H)
            else:
                weight = shapes[net][name.rsplit(".", 1)[0] + ".weight"] if name.endswith("bias") else shape
                bound = 1.0 / math.sqrt(int(np.prod(weight[1:])))
            arrays[name] = jax.random.uniform(k, shape, minval=-bound, maxval=bound)
        out[net] = arrays
    return out


# -- data ----------------------------------------------------------------------------------------------
@dataclasses.dataclass
class Sequences:
    """Concatenated training sequences (their ``processed_data``): ``audio (N, 81)``, ``state`` (each key of
    :data:`network.STATE_KEYS` ``(N, ...)``), ``gaze_pos (N, 3)``, ``ranges (R, 2)`` and the statistics."""

    audio: np.ndarray
    state: dict
    gaze_pos: np.ndarray
    ranges: np.ndarray
    stats: dict
    joints: dict
    parents: list
    names: list


def _resample_samples(y: np.ndarray, n: int) -> np.ndarray:
    src = np.linspace(0.0, len(y) - 1.0, len(y))
    return np.interp(np.linspace(0.0, len(y) - 1.0, n), src, y).astype(np.float32)


def build_sequences(clips, *, mirror: bool = True, progress: bool = False) -> Sequences:
    """Features of every clip, mirrored and at every length ratio, and their statistics (module doc)."""
    from tqdm.auto import tqdm

    from jaxgest.audio import speech_features
    from jaxgest.motion.datasets import load_clip_audio, resample_motion
    from jaxgest.motion.mirroring import mirror as mirror_motion
    from jaxgest.zeggs.official import features
    from jaxgest.zeggs.official.network import STATE_KEYS

    if not clips:
        raise DataError("no clips with speech to train on")
    skeleton = clips[0].motion.skeleton
    joints = features.root_joints(skeleton)
    parts, ranges, start = [], [], 0
    for clip in tqdm(clips, desc="features", disable=not progress, leave=False):
        if clip.motion.skeleton.names != skeleton.names:
            raise DataError(f"{clip.path}: skeleton differs from {clips[0].path}; one rig per training")
        y, sr = load_clip_audio(clip)
        base = resample_motion(clip.motion, FPS)
        for motion in [base] + ([mirror_motion(base)] if mirror else []):
            for ratio in LEN_RATIOS:
                m, a = motion, y
                if ratio != 1.0:
                    n = max(4, int(ratio * motion.num_frames))
                    m = resample_motion(motion.replace(fps=FPS * motion.num_frames / n), FPS)
                    a = _resample_samples(y, max(1, int(ratio * len(y))))
                feats = speech_features(a, sr=sr, fps=FPS, method="authors")
                n = min(len(feats), m.num_frames)
                if n < 8:
                    continue
                st = features.pose_state(m.replace(rotations=m.rotations[:n], translations=m.translations[:n]),
                                         joints)
                parts.append((feats[:n], st))
                ranges.append((start, start + n))
                start += n
    if not parts:
        raise DataError("every clip is too short to train on (8 frames at 60 fps at least)")
    audio = np.concatenate([p[0] for p in parts]).astype(np.float32)
    state = {k: np.concatenate([p[1][k] for p in parts]).astype(np.float32) for k in STATE_KEYS}
    gaze = np.concatenate([p[1]["gaze_pos"] for p in parts]).astype(np.float32)
    gaze_dir = np.concatenate([p[1]["gaze_dir"] for p in parts]).astype(np.float64)
    ranges = np.asarray(ranges, np.int64)
    return Sequences(audio, state, gaze, ranges, statistics(audio, state, gaze_dir, ranges), joints,
                     [int(p) for p in skeleton.parents], list(skeleton.names))


def statistics(audio, state, gaze_dir, ranges) -> dict:
    """Their ``data_pipeline`` statistics (frames 2 .. n-2 of every range): input mean per channel and one
    std per group (+1e-10), output std per channel, audio mean per channel and one std (+1e-10)."""
    mask = np.zeros(len(audio), bool)
    for s, e in ranges:
        mask[s + 2:e - 2] = True
    if not mask.any():
        raise DataError("the sequences are too short for statistics (5 frames at least)")
    n = len(audio)
    groups = [state[k].reshape(n, -1)[mask].astype(np.float64) for k in
              ("root_vel", "root_vrt", "lpos", "ltxy", "lvel", "lvrt")]
    g = gaze_dir.reshape(n, -1)[mask]
    out_std = np.concatenate([x.std(axis=0) for x in groups])
    return {
        "audio_input_mean": audio[mask].mean(axis=0).astype(np.float32),
        "audio_input_std": np.float32(audio[mask].std() + 1e-10),
        "anim_input_mean": np.concatenate([x.mean(axis=0) for x in groups + [g]]).astype(np.float32),
        "anim_input_std": np.concatenate([np.full(x.shape[1], x.std() + 1e-10) for x in groups + [g]]
                                         ).astype(np.float32),
        "anim_output_mean": np.concatenate([x.mean(axis=0) for x in groups]).astype(np.float32),
        "anim_output_std": np.maximum(out_std, 1e-10).astype(np.float32),
    }


def _example(seq: Sequences, w0: int, window: int, rng_range: tuple, length: int) -> np.ndarray:
    """Their ``get_example``: the example around ``[w0, w0 + window)`` inside its range, ``length`` frames
    (padded by repeating its tail), as the un-normalised input vector with a zero gaze slot."""
    s0, e0 = rng_range
    last = w0 + window - 1
    ext = (length - window) // 2
    ws, we = min(ext, w0 - s0), min(ext, e0 - last)
    start = max(w0 - (ws + ext - we), s0)
    end = min(min(last + (we + ext - ws), e0) + 1, len(seq.audio))
    n = end - start
    st = seq.state
    vec = np.concatenate([st[k][start:end].reshape(n, -1) for k in ("root_vel", "root_vrt", "lpos", "ltxy",
                                                                     "lvel", "lvrt")] + [np.zeros((n, 3), np.float32)], 1)
    if n < length:
        vec = np.concatenate([vec, vec[n - (length - n):]], 0) if length - n <= n else np.resize(vec, (length, vec.shape[1]))
    return vec[:length]


def batch(seq: Sequences, step: int, *, seed: int, batch_size: int, window: int, example_length: int) -> dict:
    """The batch of step ``step``: a pure function of ``(seed, step)`` (resumption replays it exactly)."""
    rng = np.random.default_rng([seed, step])
    starts = [(s, e) for s, e in seq.ranges if e - s > window + 1]
    if not starts:
        raise DataError(f"no sequence is longer than the training window ({window} frames at 60 fps)")
    counts = np.array([e - s - window for s, e in starts], np.float64)
    which = rng.choice(len(starts), size=batch_size, p=counts / counts.sum())
    length = 2 * int(rng.integers(example_length // 2, example_length + 1))
    idx, examples = [], []
    for r in which:
        s, e = starts[r]
        w0 = int(rng.integers(s, e - window))
        idx.append(np.arange(w0, w0 + window))
        examples.append(_example(seq, w0, window, (s, e), max(length, window)))
    idx = np.stack(idx)
    out = {k: v[idx] for k, v in seq.state.items()}
    # every step's examples padded to the longest possible length, with a mask: one compiled step
    longest = max(2 * example_length, window)
    ex = np.zeros((batch_size, longest, examples[0].shape[1]), np.float32)
    mask = np.zeros((batch_size, longest), bool)
    for i, e in enumerate(examples):
        ex[i, :len(e)], mask[i, :len(e)] = e, True
    out.update(audio=seq.audio[idx], gaze_pos=seq.gaze_pos[idx], example=ex, example_mask=mask)
    return out


# -- the step ------------------------------------------------------------------------------------------
def make_optimizer(options: dict) -> optax.GradientTransformation:
    """RAdam with their lr, eps and staircase decay (x ``learning_rate_decay`` every 1000 steps)."""
    t = options["train_opt"]
    schedule = optax.exponential_decay(float(t["learning_rate"]), 1000, float(t["learning_rate_decay"]),
                                       staircase=True)
    return optax.radam(schedule, eps=float(t["eps"]))


def loss_fn(params, batch_, key, step, *, stats, parents, dt: float, cond: str):
    """Negative ELBO of one batch (their ``train.py``): ``(loss, terms)``. References: Ghorbani et al. 2023,
    eqs. 1-2; :mod:`jaxgest.zeggs.official.losses`."""
    from jaxgest.zeggs.official import losses, network

    k_speech, k_style, k_eps = jax.random.split(key, 3)
    audio = (batch_["audio"] - stats["audio_input_mean"][None, None]) / stats["audio_input_std"]
    speech = network.speech_encoder(params["speech_encoder"], audio, key=k_speech)
    example = (batch_["example"] - stats["anim_input_mean"][None, None]) / stats["anim_input_std"][None, None]
    mu, logvar = network.style_encoder(params["style_encoder"], example, key=k_style, mask=batch_["example_mask"])
    e = mu + jnp.exp(0.5 * logvar) * jax.random.normal(k_eps, mu.shape)
    T = audio.shape[1]
    state0 = {k: batch_[k][:, 0] for k in network.STATE_KEYS}
    out = network.decoder(params["decoder"], state0, batch_["gaze_pos"], speech,
                          jnp.broadcast_to(e[:, None], (e.shape[0], T, e.shape[1])), stats, dt=dt, cond=cond)
    target = {k: batch_[k] for k in network.STATE_KEYS}
    terms = losses.reconstruction_terms(out, target, batch_["gaze_pos"], parents, dt)
    kl = losses.kl_divergence(mu, logvar)
    loss = losses.total_loss(terms, kl, step)
    return loss, {"loss": loss, **terms, "kl": kl, "kl_weight": losses.kl_weight(step)}


def _step(state, batch_, key, stats, static: tuple):
    """One step on a bare :class:`TrainState` (params, opt_state, step); ``static`` = (parents, dt, cond,
    options JSON): the optimiser is rebuilt from it inside, so jit's cache serves every run of one config."""
    import json

    parents, dt, cond, options_json = static
    tx = make_optimizer(json.loads(options_json))
    (_, metrics), grads = jax.value_and_grad(loss_fn, has_aux=True)(
        state.params, batch_, jax.random.fold_in(key, state.step), state.step, stats=stats, parents=list(parents),
        dt=dt, cond=cond)
    updates, opt_state = tx.update(grads, state.opt_state, state.params)
    return state.replace(params=optax.apply_updates(state.params, updates), opt_state=opt_state,
                         step=state.step + 1), metrics


train_step = jax.jit(_step, static_argnums=(4,), donate_argnums=(0,))


def options_for(preset: str) -> dict:
    if preset not in PRESETS:
        raise JaxgestError(f"unknown preset {preset!r} (authors' presets: {', '.join(PRESETS)})")
    return copy.deepcopy(PRESETS[preset])


def _loss_line(metrics: dict) -> str:
    return ", ".join(f"{k} {v:.4g}" for k, v in metrics.items() if k in ("loss", "lpos", "kl"))


def train(data_dir, workdir, *, preset: str = "authors-tiny", steps: Optional[int] = None, seed: int = 0,
          progress: bool = True, log_every: int = 25, ckpt_every: Optional[int] = None) -> dict:
    """Train (or resume) the authors' network on ``data_dir`` (module doc); returns a summary dict.

    The workdir then holds ``official.json`` + weights + statistics (read by ``zeggs generate``), orbax
    checkpoints under ``checkpoints/zeggs_official`` and ``metrics.jsonl`` (every term, the KL and its weight).
    """
    import json

    from flax.training.train_state import TrainState

    from jaxgest.motion.datasets import load_folder
    from jaxgest.runtime.training import Checkpointer, MetricsLogger, bare_state, check_intervals, check_steps, train_loop
    from jaxgest.runtime.io import atomic_output
    from jaxgest.runtime.workdir_lock import exclusive_workdir
    from jaxgest.zeggs.official import release

    check_steps(steps=steps)
    check_intervals(log_every=log_every, ckpt_every=ckpt_every)
    options = options_for(preset)
    steps = int(steps if steps is not None else preset_steps(options))
    workdir = pathlib.Path(workdir)
    t0 = time.perf_counter()
    if (workdir / "config.json").is_file():
        raise DataError(f"{workdir}: holds a jaxgest (root-frame) ZeroEGGS model; train the authors' network in a "
                        "new folder")
    with exclusive_workdir(workdir):
        workdir.mkdir(parents=True, exist_ok=True)
        clips = [c for c in load_folder(data_dir, progress=progress) if c.audio is not None]
        if not clips:
            raise DataError(f"{data_dir}: no clip has audio (ZeroEGGS needs BVH + WAV pairs)")
        seq = build_sequences(clips, progress=progress)
        stats_path = workdir / release.STATS
        if stats_path.is_file():  # a resumed run normalises as it started
            with np.load(stats_path) as z:
                seq.stats = {k: np.asarray(z[k], np.float32) for k in release.STAT_KEYS}
        else:
            with atomic_output(stats_path) as tmp:
                with open(tmp, "wb") as f:
                    np.savez(f, **seq.stats)
        J = len(seq.names)
        t = options["train_opt"]
        window, B = int(t["window"]), int(t["batchsize"])
        L = int(options["net_opt"]["style_encoder"]["example_length"])
        skeleton = clips[0].motion.skeleton
        config = {"options": options, "root_joints": seq.joints, "joints": J}
        ckpt = Checkpointer(workdir, kind=KIND, config=config, skeleton=skeleton.signature(),
                            subdir="checkpoints/zeggs_official")
        params = init_params(options, J, jax.random.key(seed))
        state = TrainState.create(apply_fn=None, params=params, tx=make_optimizer(options))
        state = ckpt.restore(bare_state(state.replace(step=jnp.asarray(0, jnp.int32))))
        start = int(jax.device_get(state.step))
        stats = {k: jnp.asarray(v) for k, v in seq.stats.items()}
        static = (tuple(seq.parents), 1.0 / FPS, "normal", json.dumps(options, sort_keys=True))
        logger = MetricsLogger(workdir, extra={"stage": KIND})
        last = {}
        state = train_loop(
            state, lambda s, b, k: train_step(s, b, k, stats, static),
            lambda i: batch(seq, i, seed=seed, batch_size=B, window=window, example_length=L),
            key=jax.random.key(seed + 1), num_steps=steps, checkpointer=ckpt, logger=logger, log_every=log_every,
            ckpt_every=ckpt_every if ckpt_every is not None else max(50, steps // 10), desc="zeggs (authors)",
            progress=progress, on_log=lambda s, m: last.update(m))
        ckpt.close()
        params = jax.device_get(state.params)
        manifest = {
            "format": release.FORMAT, "version": "trained", "name": f"jaxgest zeggs train --preset {preset}",
            "source": str(data_dir), "style_encoding_type": "example", "rnn_cond": "normal", "dt": 1.0 / FPS,
            "fps": FPS, "bone_names": seq.names, "parents": seq.parents, "label_names": [], "options": options,
            "audio_conf": {"method": "authors"}, "root_joints": seq.joints, "sha256": {},
            "trained": {"preset": preset, "steps": int(jax.device_get(state.step)), "seed": seed},
        }
        release.write_workdir(workdir, manifest, {k: {n: np.asarray(a) for n, a in v.items()} for k, v in params.items()},
                              seq.stats)
    return {"steps": steps, "start_step": start, "wall_s": time.perf_counter() - t0, "final": last,
            "sequences": len(seq.ranges), "frames": len(seq.audio)}
