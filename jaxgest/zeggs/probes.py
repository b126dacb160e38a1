"""ZeroEGGS style-embedding diagnostics: probes with controls and the content-leakage report.

* **Probes** (:func:`probe`): style embeddings (posterior means) of 2 s windows every 0.5 s of every clip;
  a closed-form ridge classifier predicts the style leave-one-content-out and the content
  leave-one-style-out, for the trained encoder and two controls on the same folds and windows: the
  encoder at its random initialisation and raw window statistics (mean + std of the pose features).
  Accuracies with 95 % CIs and paired differences over clips.
* **Leakage** (:func:`leakage`): reconstruction loss (eq. 2) of fixed target windows when the style
  embedding comes from the target's own window, the same clip apart from the target, the same style in
  another content, another style (same other content), or e = 0; paired contrasts with standard errors.

Both take a trained model (:func:`jaxgest.zeggs.inference.load_model`); :mod:`jaxgest.zeggs.evaluate`
runs them with the generation metrics.

References: Ghorbani et al. 2023, §5.1-5.2 (style generalisation, embedding space); docs/design.md §5.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from jaxgest import metrics
from jaxgest.runtime.errors import DataError


def _window_starts(frames: int, n: int, stride: int) -> list[int]:
    return list(range(0, max(1, frames - n + 1), max(1, stride))) or [0]


def _windows(model, clip, window_s: float, stride_s: Optional[float]) -> np.ndarray:
    """Normalised style-encoder inputs ``(W, n, P)`` of windows of ``window_s`` s every ``stride_s`` s
    (default: non-overlapping; at least one window)."""
    feats = model.style_features(clip.motion)
    fps = model.cfg.model.fps
    n = max(int(window_s * fps), model.cfg.model.style_min_frames)
    stride = n if stride_s is None else max(1, int(stride_s * fps))
    return np.stack([feats[s:s + n] for s in _window_starts(len(feats), n, stride)])


def style_windows(model, clip, window_s: float = 4.0, *, stride_s: Optional[float] = None,
                  params=None) -> np.ndarray:
    """Posterior means ``(W, D_e)`` of windows of ``window_s`` seconds of a clip, every ``stride_s`` seconds
    (default: non-overlapping; at least one window). ``params``: other encoder parameters (e.g. a
    random initialisation) instead of the model's."""
    import jax.numpy as jnp

    x = _windows(model, clip, window_s, stride_s)
    mu, _ = model.encode_style(model.params if params is None else params, jnp.asarray(x),
                               jnp.ones(x.shape[:2], bool))
    return np.asarray(mu)


def encode_windows(model, xs, params=None, *, batch: int = 256, with_logvar: bool = False):
    """Posterior means of many clips' windows at once: ``xs`` a list of ``(W_i, n_i, P)`` window arrays
    (:func:`_windows`), returned as a list of ``(W_i, D_e)``. Windows of equal length are encoded in
    batches of ``batch`` rows (the last padded with masked-out rows, so one compilation per length); the
    same values as :func:`style_windows` clip by clip. ``with_logvar``: also the posterior log-variances
    (a second list)."""
    import jax.numpy as jnp

    params = model.params if params is None else params
    out, out_lv = [None] * len(xs), [None] * len(xs)
    for n in sorted({x.shape[1] for x in xs}):
        idx = [i for i, x in enumerate(xs) if x.shape[1] == n]
        rows = np.concatenate([xs[i] for i in idx]).astype(np.float32)
        mus, lvs = [], []
        for s0 in range(0, len(rows), batch):
            chunk = rows[s0:s0 + batch]
            k = len(chunk)
            x = np.zeros((batch,) + chunk.shape[1:], np.float32)
            x[:k] = chunk
            mask = np.zeros((batch, n), bool)
            mask[:k] = True
            mu, logvar = model.encode_style(params, jnp.asarray(x), jnp.asarray(mask))
            mus.append(np.asarray(mu)[:k])
            lvs.append(np.asarray(logvar)[:k])
        mus, lvs = np.concatenate(mus), np.concatenate(lvs)
        k = 0
        for i in idx:
            out[i], out_lv[i] = mus[k:k + len(xs[i])], lvs[k:k + len(xs[i])]
            k += len(xs[i])
    return (out, out_lv) if with_logvar else out


def statistics_windows(model, clip, window_s: float = 4.0, *, stride_s: Optional[float] = None) -> np.ndarray:
    """The raw-statistics control: per-channel mean and std ``(W, 2P)`` of the normalised pose features of
    the same windows as :func:`style_windows` (no network)."""
    x = _windows(model, clip, window_s, stride_s)
    return np.concatenate([x.mean(1), x.std(1)], axis=1)


def mean_se(d) -> dict:
    """Mean, standard error (std ddof 1 / sqrt(n); 0 for n = 1), 95 % normal CI half-width, z = mean / SE
    (None when SE = 0) and n."""
    d = np.asarray(d, np.float64)
    se = float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else 0.0
    m = float(d.mean())
    return {"mean": m, "standard_error": se, "ci95_half_width": 1.96 * se, "z": m / se if se > 0 else None,
            "n": int(len(d))}


_mean_se = mean_se  # the earlier private name, kept for its importers


def probe_folds(groups) -> list[tuple]:
    """The folds of a leave-one-group-out probe: ``(group, train indices, test indices)`` for every group
    (sorted by ``str``); a clip is tested exactly once, in its group's fold, by a probe fitted on the clips
    of all other groups. Raises :class:`DataError` for fewer than two groups."""
    groups = list(groups)
    folds = []
    for g in sorted(set(groups), key=str):
        test = [i for i, h in enumerate(groups) if h == g]
        train = [i for i, h in enumerate(groups) if h != g]
        if not train:
            raise DataError("probe: one fold holds every clip (need at least two groups)")
        folds.append((g, train, test))
    return folds


def unit_means(per_clip, units) -> tuple[list, list]:
    """The mean of ``per_clip`` values within each unit (e.g. the synthetic dataset a clip comes from):
    ``(sorted unit names, means)``. Each clip weighs the same within its unit."""
    per_clip, units = np.asarray(per_clip, np.float64), list(units)
    names = sorted(set(units), key=str)
    return names, [float(per_clip[[i for i, u in enumerate(units) if u == n]].mean()) for n in names]


def fold_predictions(features, labels, groups) -> list:
    """Per clip, the labels its windows are predicted by the leave-one-group-out probe of
    :func:`grouped_probe` (one :func:`jaxgest.metrics.linear_probe_predict` fit per :func:`probe_folds`
    fold, on the windows of the clips of all other groups)."""
    labels = list(labels)
    preds = [None] * len(features)
    for _, train, test in probe_folds(groups):
        xtr = np.concatenate([features[i] for i in train])
        ytr = np.concatenate([[labels[i]] * len(features[i]) for i in train])
        pred = metrics.linear_probe_predict(xtr, ytr, np.concatenate([features[i] for i in test]))
        k = 0
        for i in test:
            preds[i] = list(pred[k:k + len(features[i])])
            k += len(features[i])
    return preds


def grouped_probe(features, labels, groups, units=None) -> dict:
    """Leave-one-group-out linear probe (:func:`jaxgest.metrics.linear_probe_predict`, one fit per fold).

    features: one ``(W_i, D)`` array of window features per clip; labels: the clip's label to predict;
    groups: the clip's fold (e.g. its content when predicting style, :func:`probe_folds`). For every group
    the probe is fitted on the windows of the clips of all other groups and predicts that group's windows,
    so every window is predicted once, by a probe that saw neither its clip nor any clip sharing its group.
    Returns the accuracy over all windows, the per-clip accuracies (fraction of a clip's windows right) and
    their standard error and 95 % CI over clips (the clips are the independent units), the chance level
    ``1 / labels`` and counts. ``units`` (one per clip, e.g. the dataset a clip was generated in): also the
    per-unit mean accuracies and their SE / CI over units (``unit_mean``), for when clips of one unit may
    not be independent.
    """
    labels, groups = list(labels), list(groups)
    preds = fold_predictions(features, labels, groups)
    right = [sum(p == y for p in ps) for ps, y in zip(preds, labels)]
    per_clip = np.array([r / len(ps) for r, ps in zip(right, preds)], np.float64)
    correct, total = int(sum(right)), int(sum(len(ps) for ps in preds))
    out = {"accuracy": float(correct / total), "per_clip": per_clip.tolist(), "clip_mean": _mean_se(per_clip),
           "chance": 1.0 / len(set(labels)), "clips": len(features), "windows": int(total),
           "folds": len(set(groups))}
    if units is not None:
        out["unit_names"], out["per_unit"] = unit_means(per_clip, units)
        out["unit_mean"] = _mean_se(out["per_unit"])
    return out


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
          stride_s: Optional[float] = PROBE_STRIDE_S, units=None, progress: bool = False) -> dict:
    """Style and content probes of the trained style encoder, beside two controls on the same folds.

    Encoders: ``trained`` (posterior means), ``random_init`` (the same architecture at the initialisation
    the model was trained from: ``init_params(cfg.model, key(seed))`` with the training seed unless ``seed``
    is given) and ``raw_statistics`` (:func:`statistics_windows`: window mean + std of the pose features).
    Windows of ``window_s`` s every ``stride_s`` s. The style probe is leave-one-content-out (a clip's style
    is predicted by a probe fitted on the clips of the *other* contents, so it cannot recognise the
    content's gestures); the content probe is leave-one-style-out. Paired per-clip differences of the
    trained encoder against each control, with standard errors over clips. When every clip has its own
    content (e.g. ZEGGS files) leave-one-content-out is leave-one-clip-out. ``units`` (one per clip, e.g.
    the synthetic dataset of a pooled set, :func:`pooled_probe`): accuracies and paired differences also
    with their SE over units (``unit_mean``, ``trained_minus_by_unit``).
    """
    import jax
    from tqdm.auto import tqdm

    from jaxgest.zeggs.model import init_params

    clips = [c for c in clips]
    if len({c.style for c in clips}) < 2 or len({c.content for c in clips}) < 2:
        raise DataError("style probe needs clips of at least two styles and two contents")
    if units is not None and len(list(units)) != len(clips):
        raise DataError(f"probe: {len(list(units))} units for {len(clips)} clips")
    train_seed = int(model.meta.get("seed", 0)) if seed is None else int(seed)
    random_params = init_params(model.cfg.model, jax.random.key(train_seed))
    xs = [_windows(model, c, window_s, stride_s)
          for c in tqdm(clips, desc="probe windows", disable=not progress, leave=False)]
    feats = {"trained": encode_windows(model, xs), "random_init": encode_windows(model, xs, random_params),
             "raw_statistics": [np.concatenate([x.mean(1), x.std(1)], axis=1) for x in xs]}  # statistics_windows
    del xs
    styles, contents = [c.style for c in clips], [c.content for c in clips]
    out = {"style": {}, "content": {}, "window_s": window_s, "stride_s": stride_s, "random_init_seed": train_seed,
           "protocol": "style: leave-one-content-out; content: leave-one-style-out; SE over clips"
           + ("" if units is None else " and over units")}
    for name in feats:
        out["style"][name] = grouped_probe(feats[name], styles, contents, units)
        out["content"][name] = grouped_probe(feats[name], contents, styles, units)
    for task in ("style", "content"):
        t = out[task]["trained"]
        out[task]["trained_minus"] = {k: _mean_se(np.subtract(t["per_clip"], out[task][k]["per_clip"]))
                                      for k in ("random_init", "raw_statistics")}
        if units is not None:
            out[task]["trained_minus_by_unit"] = {
                k: _mean_se(np.subtract(t["per_unit"], out[task][k]["per_unit"]))
                for k in ("random_init", "raw_statistics")}
        for k in feats:
            out[task][k].pop("per_clip")
    out["style_variance_share"] = variance_share(feats["trained"], styles)
    out["content_variance_share"] = variance_share(feats["trained"], contents)
    # flat keys kept for readers of the earlier layout
    out["accuracy"] = out["style"]["trained"]["accuracy"]
    out["chance"] = out["style"]["trained"]["chance"]
    out["styles"] = sorted(set(styles))
    out["test_windows"] = out["style"]["trained"]["windows"]
    return out


def pooled_probe(model, datasets, *, progress: bool = False, **kw) -> dict:
    """:func:`probe` on the clips of several datasets pooled (e.g. synthetic sets of other ``synth`` seeds:
    the same contents and styles, new scripts and performances), with the dataset as the unit of the
    second CI. The folds stay leave-one-content-out over the pooled set: a content's clips of *every*
    dataset are held out together. datasets: ``(name, clips)`` pairs."""
    clips, units, names = [], [], []
    for name, cs in datasets:
        cs = list(cs)
        if not cs:
            raise DataError(f"{name}: no clips")
        clips += cs
        units += [str(name)] * len(cs)
        names.append(str(name))
    if len(set(names)) != len(names):
        raise DataError("pooled probe: two datasets with the same name")
    out = probe(model, clips, units=units, progress=progress, **kw)
    out["datasets"] = names
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


def _recon_fn(cfg):
    """Jitted per-target reconstruction loss (eq. 2, no KL, no dropout) of a batch given the embedding
    (``cfg``: the full :class:`jaxgest.zeggs.config.Config`)."""
    import jax
    import jax.numpy as jnp

    from jaxgest.zeggs import losses
    from jaxgest.zeggs.model import ZeggsModel

    model = ZeggsModel(cfg.model)

    def f(params, batch, e, mean, std):
        s = model.apply({"params": params}, batch["speech"], method=ZeggsModel.encode_speech)
        out = model.apply({"params": params}, s, e, batch["pose"][:, 0], batch["root_position"][:, 0],
                          batch["root_rotation"][:, 0], batch["facing"], mean, std, method=ZeggsModel.generate)
        m, sd = mean[None, None], std[None, None]
        terms = losses.reconstruction_terms(out["pose"] * sd + m, out["root_position"], out["root_rotation"],
                                            batch["pose"] * sd + m, batch["root_position"],
                                            batch["root_rotation"], cfg=cfg.model)
        return losses.total_loss(terms, jnp.zeros(e.shape[0]), jnp.zeros(()), cfg=cfg.train)

    return jax.jit(f, compiler_options=cfg.inference.compiler_options)


def leakage(model, clips, *, targets_per_clip: int = 3) -> dict:
    """The leakage report of a trained model on clips with audio: reconstruction loss (eq. 2) of fixed
    target windows with the style embedding (posterior mean) of each source of :func:`leakage_plan`, and
    the paired contrasts (:func:`leakage_statistics`). Windows: the model's ``window`` and
    ``style_window_max`` frames."""
    import jax.numpy as jnp

    from jaxgest.zeggs import data as zdata

    cfg = model.cfg.model
    seqs = [zdata.clip_sequences(c, fps=cfg.fps, mirror=False, speeds=(1.0,), loudness=cfg.loudness,
                                  speech_method=cfg.speech_features)[0] for c in clips]
    T, M = model.cfg.train.window, model.cfg.train.style_window_max
    plan = leakage_plan(clips, [s.frames for s in seqs], window=T, style_len=M, targets_per_clip=targets_per_clip)
    if not plan:
        raise DataError(f"leakage: no clip is long enough for a {T}-frame target and a disjoint {M}-frame window")
    rows = [zdata.target_arrays(seqs[p["clip"]], p["t0"], T, model.pose_stats, model.speech_stats) for p in plan]
    batch = {k: jnp.asarray(np.stack([r[k] for r in rows]), jnp.float32) for k in rows[0]}
    fn = _recon_fn(model.cfg)
    by_source = {}
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
            mu, _ = model.encode_style(model.params, jnp.asarray(x), jnp.ones(x.shape[:2], bool))
            e = np.asarray(mu, np.float32)
        loss = np.asarray(fn(model.params, batch, jnp.asarray(e), model.pose_mean, model.pose_std),
                          np.float64)
        by_source[name] = np.where(have, loss, np.nan)
    out = leakage_statistics(by_source, [p["clip"] for p in plan])
    out.update({"window": T, "style_window": M, "targets_per_clip": targets_per_clip,
                "embedding": "posterior mean of each source window"})
    return out
