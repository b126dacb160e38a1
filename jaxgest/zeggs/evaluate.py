"""ZeroEGGS evaluation: style/content probes with controls, a content-leakage report, beat alignment
against a shuffled control, and the Fréchet distance between motion-feature statistics of generated and
real clips (SPEC §5).

* **Probes** (:func:`probe`): style embeddings (posterior means) of 2 s windows every 0.5 s of every clip;
  a closed-form ridge classifier predicts the style leave-one-content-out and the content
  leave-one-style-out, for the trained encoder and two controls on the same folds and windows: the
  encoder at its random initialisation and raw window statistics (mean + std of the pose features).
  Accuracies with 95 % CIs and paired differences over clips.
* **Leakage** (:func:`leakage`): reconstruction loss (eq. 2) of fixed target windows when the style
  embedding comes from the target's own window, the same clip apart from the target, the same style in
  another content, another style (same other content), or e = 0; paired contrasts with standard errors.
* **Beat alignment**: for each test clip with audio, gestures are generated from its audio in its style,
  with another recording of that style (a training-half clip of another content when there is one, see
  :func:`style_example`) as the zero-shot style example, so the example's timing cannot leak; kinematic
  beats (minima of smoothed hand speed) are scored against the audio's onsets (BeatAlign, sigma 0.1 s) and
  against circularly shifted onsets (the shuffled control), with the per-clip paired difference (mean,
  standard error over clips, clips above the control). Also reported for the real motion.
* **Fréchet distance** between Gaussian fits of per-frame motion features (root-frame joint positions and
  velocities) of the generated clips and of the real clips; the same distance between the real training
  clips and the real test clips is reported as the floor to compare with.

References: Ghorbani et al. 2023, §5.1-5.2 (style generalisation, embedding space); SPEC §5; Li et al. 2021
(BeatAlign); Heusel et al. 2017 (Fréchet distance).
"""

from __future__ import annotations

import collections
import functools
from typing import Optional

import numpy as np

from jaxgest import metrics
from jaxgest.errors import DataError
from jaxgest.motion import body as B
from jaxgest.motion import kinematics as K
from jaxgest.motion.datasets import load_clip_audio, load_folder
from jaxgest.zeggs import features as Fe
from jaxgest.zeggs.inference import load_model


def _split_by_style(clips, seed: int = 0):
    by_style = collections.defaultdict(list)
    for c in clips:
        by_style[c.style].append(c)
    rng = np.random.default_rng(seed)
    train, test = [], []
    for style in sorted(by_style):
        group = sorted(by_style[style], key=lambda c: str(c.path))
        rng.shuffle(group)
        if len(group) < 2:
            train.extend(group)
            continue
        half = len(group) // 2
        test.extend(group[:half])
        train.extend(group[half:])
    return train, test


def _window_starts(frames: int, n: int, stride: int) -> list[int]:
    return list(range(0, max(1, frames - n + 1), max(1, stride))) or [0]


def style_windows(model, clip, window_s: float = 4.0, *, stride_s: Optional[float] = None,
                  params=None) -> np.ndarray:
    """Posterior means ``(W, D_e)`` of windows of ``window_s`` seconds of a clip, every ``stride_s`` seconds
    (default: non-overlapping; at least one window). ``params``: other encoder parameters (e.g. a
    random initialisation) instead of the model's."""
    import jax.numpy as jnp

    feats = model.style_features(clip.motion)
    n = max(int(window_s * model.cfg.fps), model.cfg.style_min_frames)
    stride = n if stride_s is None else max(1, int(stride_s * model.cfg.fps))
    x = np.stack([feats[s:s + n] for s in _window_starts(len(feats), n, stride)])
    mu, _ = model._encode_style(model.params if params is None else params, jnp.asarray(x),
                                jnp.ones(x.shape[:2], bool))
    return np.asarray(mu)


def statistics_windows(model, clip, window_s: float = 4.0, *, stride_s: Optional[float] = None) -> np.ndarray:
    """The raw-statistics control: per-channel mean and std ``(W, 2P)`` of the normalised pose features of
    the same windows as :func:`style_windows` (no network)."""
    feats = model.style_features(clip.motion)
    n = max(int(window_s * model.cfg.fps), model.cfg.style_min_frames)
    stride = n if stride_s is None else max(1, int(stride_s * model.cfg.fps))
    return np.stack([np.concatenate([feats[s:s + n].mean(0), feats[s:s + n].std(0)])
                     for s in _window_starts(len(feats), n, stride)])


def _mean_se(d) -> dict:
    """Mean, standard error (std ddof 1 / sqrt(n); 0 for n = 1), 95 % normal CI half-width, z = mean / SE
    (None when SE = 0) and n."""
    d = np.asarray(d, np.float64)
    se = float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else 0.0
    m = float(d.mean())
    return {"mean": m, "standard_error": se, "ci95_half_width": 1.96 * se, "z": m / se if se > 0 else None,
            "n": int(len(d))}


def grouped_probe(features, labels, groups) -> dict:
    """Leave-one-group-out linear probe (:func:`jaxgest.metrics.linear_probe_accuracy`).

    features: one ``(W_i, D)`` array of window features per clip; labels: the clip's label to predict;
    groups: the clip's fold (e.g. its content when predicting style). For every group the probe is fitted on
    the windows of the clips of all other groups and scored on that group's windows, so every window is
    predicted once, by a probe that saw neither its clip nor any clip sharing its group. Returns the accuracy
    over all windows, the per-clip accuracies (fraction of a clip's windows right) and their standard error
    and 95 % CI over clips (the clips are the independent units), the chance level ``1 / labels`` and counts.
    """
    labels, groups = list(labels), list(groups)
    per_clip = np.zeros(len(features))
    correct = total = 0
    for g in sorted(set(groups), key=str):
        test = [i for i, h in enumerate(groups) if h == g]
        train = [i for i, h in enumerate(groups) if h != g]
        if not train:
            raise DataError("probe: one fold holds every clip (need at least two groups)")
        xtr = np.concatenate([features[i] for i in train])
        ytr = np.concatenate([[labels[i]] * len(features[i]) for i in train])
        for i in test:
            acc = metrics.linear_probe_accuracy(xtr, ytr, features[i], [labels[i]] * len(features[i]))
            per_clip[i] = acc
            correct += acc * len(features[i])
            total += len(features[i])
    return {"accuracy": float(correct / total), "per_clip": per_clip.tolist(), "clip_mean": _mean_se(per_clip),
            "chance": 1.0 / len(set(labels)), "clips": len(features), "windows": int(total),
            "folds": len(set(groups))}


def variance_share(features, labels) -> float:
    """Share of the total variance of the window features explained by ``labels`` (between-class variance
    of the class means over the total variance, summed over dimensions; 1 = the label fixes the features)."""
    x = np.concatenate(features).astype(np.float64)
    y = np.concatenate([[lab] * len(f) for f, lab in zip(features, labels)])
    total = float(((x - x.mean(0)) ** 2).sum())
    between = sum(float((y == c).sum() * ((x[y == c].mean(0) - x.mean(0)) ** 2).sum()) for c in set(y.tolist()))
    return between / total if total > 0 else 0.0


PROBE_WINDOW_S, PROBE_STRIDE_S = 2.0, 0.5


def probe(model, clips, *, seed: Optional[int] = None, window_s: float = PROBE_WINDOW_S,
          stride_s: Optional[float] = PROBE_STRIDE_S) -> dict:
    """Style and content probes of the trained style encoder, beside two controls on the same folds.

    Encoders: ``trained`` (posterior means), ``random_init`` (the same architecture at the initialisation
    the model was trained from: ``init_params(cfg, PRNGKey(seed))`` with the training seed unless ``seed``
    is given) and ``raw_statistics`` (:func:`statistics_windows`: window mean + std of the pose features).
    Windows of ``window_s`` s every ``stride_s`` s. The style probe is leave-one-content-out (a clip's style
    is predicted by a probe fitted on the clips of the *other* contents, so it cannot recognise the
    content's gestures); the content probe is leave-one-style-out. Paired per-clip differences of the
    trained encoder against each control, with standard errors over clips. When every clip has its own
    content (e.g. ZEGGS files) leave-one-content-out is leave-one-clip-out.
    """
    import jax

    from jaxgest.zeggs.steps import init_params

    clips = [c for c in clips]
    if len({c.style for c in clips}) < 2 or len({c.content for c in clips}) < 2:
        raise DataError("style probe needs clips of at least two styles and two contents")
    train_seed = int(model.meta.get("seed", 0)) if seed is None else int(seed)
    random_params = init_params(model.cfg, jax.random.PRNGKey(train_seed))
    encoders = {
        "trained": lambda c: style_windows(model, c, window_s, stride_s=stride_s),
        "random_init": lambda c: style_windows(model, c, window_s, stride_s=stride_s, params=random_params),
        "raw_statistics": lambda c: statistics_windows(model, c, window_s, stride_s=stride_s),
    }
    styles, contents = [c.style for c in clips], [c.content for c in clips]
    out = {"style": {}, "content": {}, "window_s": window_s, "stride_s": stride_s, "random_init_seed": train_seed,
           "protocol": "style: leave-one-content-out; content: leave-one-style-out; SE over clips"}
    feats = {}
    for name, fn in encoders.items():
        feats[name] = [fn(c) for c in clips]
        out["style"][name] = grouped_probe(feats[name], styles, contents)
        out["content"][name] = grouped_probe(feats[name], contents, styles)
    for task in ("style", "content"):
        t = out[task]["trained"]["per_clip"]
        out[task]["trained_minus"] = {k: _mean_se(np.subtract(t, out[task][k]["per_clip"]))
                                      for k in ("random_init", "raw_statistics")}
        for k in encoders:
            out[task][k].pop("per_clip")
    out["style_variance_share"] = variance_share(feats["trained"], styles)
    out["content_variance_share"] = variance_share(feats["trained"], contents)
    # flat keys kept for readers of the earlier layout
    out["accuracy"] = out["style"]["trained"]["accuracy"]
    out["chance"] = out["style"]["trained"]["chance"]
    out["styles"] = sorted(set(styles))
    out["test_windows"] = out["style"]["trained"]["windows"]
    return out


# --------------------------------------------------------------------------------------------------------
# Leakage: how much of the reconstruction is owed to the style window seeing the target's own content

LEAKAGE_SOURCES = ("own_window", "same_clip_disjoint", "same_style_other_content", "other_style", "zero")
LEAKAGE_CONTRASTS = {  # name: (minuend, subtrahend); positive = the subtrahend reconstructs better
    "other_style - same_style_other_content": ("other_style", "same_style_other_content"),
    "zero - same_style_other_content": ("zero", "same_style_other_content"),
    "same_style_other_content - same_clip_disjoint": ("same_style_other_content", "same_clip_disjoint"),
    "same_clip_disjoint - own_window": ("same_clip_disjoint", "own_window"),
}


def leakage_plan(clips, frames, *, window: int, style_len: int, targets_per_clip: int = 3) -> list[dict]:
    """Fixed targets and, for each, the style window of every leakage source.

    clips: objects with ``style`` and ``content``; frames: their lengths at the model rate. For clip ``i``,
    ``targets_per_clip`` targets of ``window`` frames start at ``(F - window) (k + 1/2) / K``. Sources
    (``(clip index, start)`` of a window of ``style_len`` frames, or None for e = 0):

    * ``own_window``: the same clip, centred on the target (contains it; the paper's training case);
    * ``same_clip_disjoint``: the same clip, centred in the larger gap beside the target, not overlapping it;
    * ``same_style_other_content``: clip (content k, same style), k another content (cycled over targets);
    * ``other_style``: clip (content k, another style): the same content k as the previous source, so the
      two differ by the style only (falls back to any clip of another style);
    * ``zero``: e = 0.

    Windows in other clips sit at the same relative position as ``own_window``. Clips too short for a
    target plus a disjoint window are skipped; a source that does not exist is None for that target.
    """
    by = {(c.content, c.style): i for i, c in enumerate(clips)}
    contents = sorted({c.content for c in clips}, key=str)
    styles = sorted({c.style for c in clips}, key=str)
    plan = []

    def at(j, rel):
        return j, int(round(rel * max(0, frames[j] - style_len)))

    for i, c in enumerate(clips):
        F = frames[i]
        if F < window + style_len:
            continue
        for k in range(targets_per_clip):
            t0 = int(round((F - window) * (k + 0.5) / targets_per_clip))
            own = min(max(0, t0 + window // 2 - style_len // 2), F - style_len)
            rel = own / max(1, F - style_len)
            left, right = t0, F - t0 - window
            if max(left, right) < style_len:
                continue
            d0 = (left - style_len) // 2 if left >= right else t0 + window + (right - style_len) // 2
            src = {"own_window": (i, own), "same_clip_disjoint": (i, d0), "same_style_other_content": None,
                   "other_style": None, "zero": None}
            ci = contents.index(c.content)
            others = [contents[(ci + 1 + k + r) % len(contents)] for r in range(len(contents) - 1)]
            si = styles.index(c.style)
            other_styles = [styles[(si + 1 + k + r) % len(styles)] for r in range(len(styles) - 1)]
            for kc in others:
                if (kc, c.style) not in by:
                    continue
                src["same_style_other_content"] = at(by[(kc, c.style)], rel)
                paired = [by[(kc, s)] for s in other_styles if (kc, s) in by]
                if paired:
                    src["other_style"] = at(paired[0], rel)
                break
            if src["same_style_other_content"] is None:
                same = [j for j, o in enumerate(clips) if o.style == c.style and o.content != c.content]
                src["same_style_other_content"] = at(same[k % len(same)], rel) if same else None
            if src["other_style"] is None:
                diff = [j for j, o in enumerate(clips) if o.style != c.style]
                src["other_style"] = at(diff[k % len(diff)], rel) if diff else None
            plan.append({"clip": i, "t0": t0, "sources": src})
    return plan


def leakage_statistics(losses: dict, groups) -> dict:
    """Mean loss per source and the paired contrasts of :data:`LEAKAGE_CONTRASTS`.

    losses: source name -> per-target losses ``(N,)`` (NaN where the source does not exist); groups: the
    target's clip ``(N,)``. Differences are per target, averaged per clip, then mean / SE / z over clips
    (the targets of one clip share it, so the clip is the independent unit).
    """
    groups = np.asarray(groups)
    out = {"mean_loss": {k: float(np.nanmean(v)) for k, v in losses.items()}, "contrasts": {},
           "targets": int(len(groups)), "clips": int(len(set(groups.tolist())))}
    for name, (a, b) in LEAKAGE_CONTRASTS.items():
        if a not in losses or b not in losses:
            continue
        d = np.asarray(losses[a], np.float64) - np.asarray(losses[b], np.float64)
        per = [float(np.nanmean(d[groups == g])) for g in sorted(set(groups.tolist())) if np.any(np.isfinite(d[groups == g]))]
        if per:
            out["contrasts"][name] = _mean_se(per)
    return out


@functools.lru_cache(maxsize=4)
def _recon_fn(cfg):
    """Jitted per-target reconstruction loss (eq. 2, no KL, no dropout) of a batch given the embedding."""
    import jax
    import jax.numpy as jnp

    from jaxgest.zeggs import losses as L
    from jaxgest.zeggs.steps import ZeggsModel

    model = ZeggsModel(cfg)

    def f(params, batch, e, mean, std):
        s = model.apply({"params": params}, batch["speech"], method=ZeggsModel.encode_speech)
        out = model.apply({"params": params}, s, e, batch["pose"][:, 0], batch["root_position"][:, 0],
                          batch["root_rotation"][:, 0], batch["facing"], mean, std, method=ZeggsModel.generate)
        m, sd = mean[None, None], std[None, None]
        terms = L.reconstruction_terms(out["pose"] * sd + m, out["root_position"], out["root_rotation"],
                                       batch["pose"] * sd + m, batch["root_position"], batch["root_rotation"],
                                       cfg=cfg)
        return L.total_loss(terms, jnp.zeros(e.shape[0]), jnp.zeros(()), cfg=cfg)

    return jax.jit(f, compiler_options=cfg.compiler_options)


def leakage(model, clips, *, targets_per_clip: int = 3) -> dict:
    """The leakage report of a trained model on clips with audio: reconstruction loss (eq. 2) of fixed
    target windows with the style embedding (posterior mean) of each source of :func:`leakage_plan`, and
    the paired contrasts (:func:`leakage_statistics`). Windows: the model's ``window`` and
    ``style_window_max`` frames."""
    import jax.numpy as jnp

    from jaxgest.zeggs import data as zdata

    cfg = model.cfg
    seqs = [zdata.clip_sequences(c, fps=cfg.fps, mirror=False, speeds=(1.0,), loudness=cfg.loudness)[0] for c in clips]
    T, M = cfg.window, cfg.style_window_max
    plan = leakage_plan(clips, [s.frames for s in seqs], window=T, style_len=M, targets_per_clip=targets_per_clip)
    if not plan:
        raise DataError(f"leakage: no clip is long enough for a {T}-frame target and a disjoint {M}-frame window")
    rows = [zdata.target_arrays(seqs[p["clip"]], p["t0"], T, model.pose_stats, model.speech_stats) for p in plan]
    batch = {k: jnp.asarray(np.stack([r[k] for r in rows]), jnp.float32) for k in rows[0]}
    fn = _recon_fn(cfg)
    losses = {}
    for name in LEAKAGE_SOURCES:
        if name == "zero":
            e = np.zeros((len(plan), cfg.style_embedding), np.float32)
            have = np.ones(len(plan), bool)
        else:
            have = np.array([p["sources"][name] is not None for p in plan])
            x = np.zeros((len(plan), M, cfg.pose_dim), np.float32)
            for r, p in enumerate(plan):
                if p["sources"][name] is not None:
                    j, s0 = p["sources"][name]
                    x[r] = model.pose_stats.normalize(seqs[j].pose[s0:s0 + M])
            mu, _ = model._encode_style(model.params, jnp.asarray(x), jnp.ones(x.shape[:2], bool))
            e = np.asarray(mu, np.float32)
        loss = np.asarray(fn(model.params, batch, jnp.asarray(e), model._mean, model._std), np.float64)
        losses[name] = np.where(have, loss, np.nan)
    out = leakage_statistics(losses, [p["clip"] for p in plan])
    out.update({"window": T, "style_window": M, "targets_per_clip": targets_per_clip,
                "embedding": "posterior mean of each source window"})
    return out


def _hand_indices(motion):
    return B.joint_indices(motion.skeleton, B.HANDS)


def beat_scores(motion, audio, sr: int, *, seed: int = 0) -> dict:
    """BeatAlign of a motion against its audio's onsets and against shifted onsets."""
    pos = K.forward_kinematics(motion)
    speed = metrics.hand_speed(pos, motion.fps, _hand_indices(motion))
    beats = metrics.kinematic_beats(speed, motion.fps)
    onsets = metrics.onset_times(audio, sr)
    duration = motion.num_frames / motion.fps
    return {"aligned": metrics.beat_alignment(beats, onsets),
            "shuffled": metrics.shuffled_beat_alignment(beats, onsets, duration, seed=seed)}


def style_example(clip, others):
    """The style example for generating ``clip``: another recording of its style (the first of ``others``
    with the same style and another content when there is one, else another file), else the clip itself."""
    same = [o for o in others if o.style == clip.style and o.path != clip.path]
    other_content = [o for o in same if o.content != clip.content]
    return (other_content or same or [clip])[0]


def paired_difference(scores) -> dict:
    """Per-clip BeatAlign minus its shuffled control: mean, standard error of the mean, clips above.

    scores: list of :func:`beat_scores` dicts (one per clip). The clips are the independent units, so the
    standard error is std(diff, ddof=1) / sqrt(clips) (0 for one clip).
    """
    d = np.array([s["aligned"] - s["shuffled"] for s in scores], np.float64)
    se = float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else 0.0
    return {"mean": float(d.mean()), "standard_error": se, "clips_above": int(np.sum(d > 0)), "clips": len(d)}


def motion_statistics_features(motion) -> np.ndarray:
    """Per-frame features for the Fréchet distance: root-frame joint positions and velocities (F, 6J)."""
    f = Fe.extract_features(motion)["features"].astype(np.float64)
    lay = Fe.PoseLayout(motion.skeleton.num_joints)
    return np.concatenate([f[:, lay.local_positions], f[:, lay.local_velocities]], axis=1)


def evaluate(workdir, data_dir, *, seed: int = 0, max_clips: Optional[int] = None, progress: bool = True) -> dict:
    """All three figures for a trained model on a data folder (see the module docstring)."""
    from tqdm.auto import tqdm

    model = load_model(workdir)
    clips = load_folder(data_dir)
    if not clips:
        raise DataError(f"{data_dir}: no clips")
    result = {"probe": probe(model, clips)}
    with_audio = [c for c in clips if c.audio is not None]
    result["leakage"] = leakage(model, with_audio) if with_audio else None
    train, test = _split_by_style([c for c in clips if c.audio is not None], seed)
    test = test[:max_clips] if max_clips else test
    if not test:
        raise DataError(f"{data_dir}: no test clip with audio for beat alignment")
    gen_scores, real_scores, gen_feats, real_feats = [], [], [], []
    for c in tqdm(test, desc="zeggs evaluate", disable=not progress, leave=False):
        audio, sr = load_clip_audio(c)
        gen = model.generate(audio, [style_example(c, train).motion], sr=sr, seed=seed, name=f"{c.path.stem}_gen")
        try:
            gen_scores.append(beat_scores(gen, audio, sr, seed=seed))
            real_scores.append(beat_scores(c.motion, audio, sr, seed=seed))
        except DataError:
            continue  # a clip without kinematic beats has no defined score
        gen_feats.append(motion_statistics_features(gen))
        real_feats.append(motion_statistics_features(c.motion))
    if not gen_scores:
        raise DataError("beat alignment: no test clip produced kinematic beats")

    def mean(xs, k):
        return float(np.mean([x[k] for x in xs]))

    result["beat_alignment"] = {
        "generated": mean(gen_scores, "aligned"), "generated_shuffled": mean(gen_scores, "shuffled"),
        "real": mean(real_scores, "aligned"), "real_shuffled": mean(real_scores, "shuffled"),
        "generated_vs_control": paired_difference(gen_scores), "real_vs_control": paired_difference(real_scores),
        "clips": len(gen_scores), "sigma_s": 0.1,
    }
    real_test = np.concatenate(real_feats)
    result["frechet_distance"] = {
        "generated_vs_real": metrics.frechet_distance(np.concatenate(gen_feats), real_test),
        # the floor: other real clips (the training half) against the same real test clips
        "real_train_vs_real_test": metrics.frechet_distance(
            np.concatenate([motion_statistics_features(c.motion) for c in train]), real_test) if train else None,
        "features": "root-frame joint positions and velocities",
    }
    return result


def _diff(d) -> str:
    if not d:
        return ""
    return f" (difference {d['mean']:+.3f} ± {d['standard_error']:.3f} SE, {d['clips_above']}/{d['clips']} clips above)"


def _pm(d) -> str:
    z = "n/a" if d["z"] is None else f"{d['z']:.1f}"
    return f"{d['mean']:+.3f} ± {d['standard_error']:.3f} (z = {z})"


def markdown(result: dict) -> str:
    p, b, f = result["probe"], result["beat_alignment"], result["frechet_distance"]
    lines = ["| probe (leave-one-content-out for style, leave-one-style-out for content) | trained | random init | "
             "raw statistics | chance |", "|---|---:|---:|---:|---:|"]
    for task in ("style", "content"):
        t = p[task]
        cells = [f"{t[k]['accuracy']:.3f} ± {t[k]['clip_mean']['ci95_half_width']:.3f}"
                 for k in ("trained", "random_init", "raw_statistics")]
        lines.append(f"| {task} probe accuracy (chance {t['trained']['chance']:.3f}), ± 95 % CI over "
                     f"{t['trained']['clips']} clips ({t['trained']['windows']} windows) | " + " | ".join(cells)
                     + f" | {t['trained']['chance']:.3f} |")
        lines.append(f"| {task}: trained minus control (paired over clips) | | "
                     f"{_pm(t['trained_minus']['random_init'])} | {_pm(t['trained_minus']['raw_statistics'])} | |")
    lines += [f"| share of embedding variance explained by style / content | "
              f"{p['style_variance_share']:.3f} / {p['content_variance_share']:.3f} | | | |", ""]
    lk = result.get("leakage")
    if lk:
        m = lk["mean_loss"]
        lines += ["| reconstruction loss of fixed targets, style embedding from | loss |", "|---|---:|"]
        lines += [f"| {k.replace('_', ' ')} | {m[k]:.4f} |" for k in LEAKAGE_SOURCES if k in m]
        lines += [f"| contrast {k} (mean ± SE over {lk['clips']} clips) | {_pm(v)} |"
                  for k, v in lk["contrasts"].items()]
        lines.append("")
    lines += [
        "| metric | value |",
        "|---|---:|",
        f"| BeatAlign generated / shuffled control | {b['generated']:.3f} / {b['generated_shuffled']:.3f}"
        f"{_diff(b.get('generated_vs_control'))} |",
        f"| BeatAlign real motion / shuffled control | {b['real']:.3f} / {b['real_shuffled']:.3f}"
        f"{_diff(b.get('real_vs_control'))} |",
        f"| Fréchet distance generated vs real | {f['generated_vs_real']:.4g} |",
    ]
    if f.get("real_train_vs_real_test") is not None:
        lines.append(f"| Fréchet distance real (train clips) vs real (test clips) | {f['real_train_vs_real_test']:.4g} |")
    return "\n".join(lines)
