"""Quantitative evaluation of TGST style transfer (paper 000 §4.2-4.3, Tables 1-3; SPEC §5).

* :func:`clip_errors` -- content error (eqs. 13-14, both hands, exact DTW) and style error (eqs. 15-16,
  arm-joint velocities) of one transferred clip, plus the same two errors against the ground-truth clip
  (the content performed in the target style) where the dataset has one (beyond the paper, SPEC §5).
* :func:`make_pairs` -- content/style evaluation pairs: intra-scenario (style clip of the same content),
  inter-scenario (of another content) or all.
* :func:`evaluate` -- per-method averages over pairs of mean / worst / w25 (Tables 2 and 3).
* :func:`metric_validity` -- Table 1: the errors of the content clip itself and of the style clip, both
  against the referential ground-truth sample.
* :func:`register_evaluate` -- ``jaxgest tgst evaluate`` (SPEC §6).

Units: BVH positions of both datasets and of the synthetic data are centimetres; hands are compared in
metres and velocities in metres per second, at the result's frame rate (a style clip at another rate is
resampled to it). The style window is theta = 128 frames at 60 fps scaled with the rate
(:func:`jaxgest.metrics.window_for_fps`; 64 at Bandai-Namco's 30 fps), hop floor(theta / 2); no frames are
trimmed (the authors' code cuts 60 frames at both ends).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from jaxgest import metrics
from jaxgest.errors import DataError
from jaxgest.motion import body, kinematics
from jaxgest.motion.skeleton import Motion
from jaxgest.tgst.model import METHODS

PAIR_MODES = ("intra", "inter", "all")
NEUTRAL = ("normal", "neutral")
STATS = ("mean", "worst", "w25")
ERROR_KEYS = ("content", "style", "gt_content", "gt_style")
CM_TO_M = 0.01
NOTES = {
    "content": "eqs. 13-14: both hands' world positions in metres, exact DTW (not FastDTW); mean/worst/w25",
    "style": "eqs. 15-16: arm-joint (8) velocities in m/s, sum over joints of ||dmean|| + ||dstd||, theta = 128 "
    "frames at 60 fps scaled with the rate, hop theta/2, no trimming; mean/worst/w25",
    "w25": "mean of the ceil(25%) largest components (at least one)",
    "gt": "gt_content / gt_style: the same errors with the dataset clip of the content in the target style",
    "averages": "each statistic averaged over the evaluated pairs (paper Tables 2/3)",
}


# --------------------------------------------------------------------------------------------------------
# Per-clip features and errors


def _joint_indices(motion: Motion, names: Sequence[str]) -> list[int]:
    sk = motion.skeleton
    joints = body.load_map(body.detect_map(sk))["joints"]
    return [sk.index(joints[n]) for n in names]


def clip_features(motion: Motion, fps: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(hands (F, 6) m, arm velocities (F, 24) m/s)`` of a motion on any mapped rig, at ``fps``.

    Hands: world positions of body.HANDS (left, right); arms: per-second velocities of body.ARMS (8 joints),
    both mapped to the rig's joint names through its joint map, positions in cm -> m. ``fps`` (default the
    motion's) resamples the motion first so velocities and windows compare at one rate.
    References: Kuriyama et al. 2022, §4.2 (6-D hand positions in metres; velocities of arm joints).
    """
    if fps is not None and abs(float(fps) - motion.fps) > 1e-9:
        from jaxgest.motion.datasets import resample_motion

        motion = resample_motion(motion, float(fps))
    pos = kinematics.forward_kinematics(motion)
    hands = metrics.hands_metres(pos, _joint_indices(motion, body.HANDS))
    arms = metrics.arm_velocities(pos, motion.fps, _joint_indices(motion, body.ARMS), scale=CM_TO_M)
    return hands, arms


def features_errors(result_feats, content_feats, style_feats, gt_feats=None, *, window: int) -> dict:
    """The errors of :func:`clip_errors` from precomputed :func:`clip_features` tuples (hands, arm vel).

    References: Kuriyama et al. 2022, eqs. 13-16.
    """
    out = {
        "content": metrics.content_error(content_feats[0], result_feats[0]),
        "style": metrics.style_error(result_feats[1], style_feats[1], window),
    }
    if gt_feats is not None:
        out["gt_content"] = metrics.content_error(gt_feats[0], result_feats[0])
        out["gt_style"] = metrics.style_error(result_feats[1], gt_feats[1], window)
    return out


def clip_errors(result: Motion, content: Motion, style: Motion, ground_truth: Motion | None = None) -> dict:
    """Errors of one transferred clip: ``{"content", "style"[, "gt_content", "gt_style"]}``.

    Each value is ``{"mean", "worst", "w25"}``. content: E^content between the content clip's and the
    result's hands (DTW-aligned, metres); style: E^style of the result's arm-joint velocities against the
    style clip's windows (theta = window_for_fps(result.fps)); gt_content / gt_style: the same two errors
    with the ground-truth clip (content performed in the target style) in place of the content and of the
    style clip, only when ``ground_truth`` is given. All clips are compared at the result's frame rate.
    Raises DataError when a clip is shorter than one style window.

    References: Kuriyama et al. 2022, eqs. 13-16 and §4.3 (imitated ground truth); SPEC §5.
    """
    fps = result.fps
    feats = [clip_features(m, fps) for m in (result, content, style)]
    gt = clip_features(ground_truth, fps) if ground_truth is not None else None
    return features_errors(*feats, gt, window=metrics.window_for_fps(fps))


# --------------------------------------------------------------------------------------------------------
# Pairs


@dataclasses.dataclass(frozen=True, eq=False)
class Pair:
    """One evaluation case: transfer the style of ``style`` onto ``content``; ``ground_truth`` (or None) is
    the dataset clip with the content's content in the style's style. Fields are dataset Clips."""

    content: object
    style: object
    ground_truth: object = None


def _is_neutral(clip, neutral) -> bool:
    return clip.style.lower() in {n.lower() for n in neutral}


def make_pairs(
    clips: Sequence,
    mode: str = "intra",
    neutral: Sequence[str] = NEUTRAL,
    max_pairs: int | None = None,
    seed: int = 0,
) -> list[Pair]:
    """Content/style pairs of a dataset (list of :class:`jaxgest.motion.datasets.Clip`).

    Content clips are the clips in a neutral style (case-insensitive names in ``neutral``); style clips are
    all clips in another style. ``mode``: "intra" pairs a content clip with the style clips of the same
    content label (paper's intra-scenario condition), "inter" with those of other contents, "all" with
    both. The ground truth is a clip with the content's content label in the style's style: another take
    than the style clip when the dataset has one, else the style clip itself (intra pairs of datasets with
    one take per content and style, e.g. Bandai-Namco), None when the dataset has no such clip (ZEGGS).
    Pairs are ordered by (content path, style path); ``max_pairs`` keeps a random subset (seeded by
    ``seed``) in that order. References: Kuriyama et al. 2022, §4.3 (intra- and inter-scenario conditions).
    """
    if mode not in PAIR_MODES:
        raise DataError(f"evaluate: unknown pair mode {mode!r} (choose from {', '.join(PAIR_MODES)})")
    by_key: dict = {}
    for c in sorted(clips, key=lambda c: str(c.path)):
        by_key.setdefault((c.content, c.style.lower()), []).append(c)
    contents = sorted((c for c in clips if _is_neutral(c, neutral)), key=lambda c: str(c.path))
    styles = sorted((c for c in clips if not _is_neutral(c, neutral)), key=lambda c: str(c.path))
    pairs = []
    for c in contents:
        for s in styles:
            same = s.content == c.content
            if (mode == "intra" and not same) or (mode == "inter" and same):
                continue
            candidates = by_key.get((c.content, s.style.lower()), [])
            others = [g for g in candidates if g is not s]
            gt = others[0] if others else (candidates[0] if candidates else None)
            pairs.append(Pair(c, s, gt))
    if max_pairs is not None:
        if max_pairs < 1:
            raise DataError(f"evaluate: --max-pairs must be >= 1, got {max_pairs}")
        if len(pairs) > max_pairs:
            keep = np.sort(np.random.default_rng(seed).choice(len(pairs), size=max_pairs, replace=False))
            pairs = [pairs[i] for i in keep]
    return pairs


# --------------------------------------------------------------------------------------------------------
# Evaluation


def _average(results: list) -> dict | None:
    """Average of ``{"mean","worst","w25"}`` dicts (the paper averages each metric over samples)."""
    if not results:
        return None
    return {k: float(np.mean([r[k] for r in results])) for k in STATS}


class _FeatureCache:
    """clip_features of dataset clips, computed once per (clip, fps)."""

    def __init__(self):
        self._cache = {}

    def __call__(self, clip, fps):
        key = (id(clip), round(float(fps), 6))
        if key not in self._cache:
            self._cache[key] = (clip, clip_features(clip.motion, fps))
        return self._cache[key][1]


def _too_short(pair: Pair, cache: _FeatureCache, fps: float, window: int) -> str:
    """Why the pair cannot be evaluated (content or style clip shorter than one style window), or ''."""
    for role, clip in (("content", pair.content), ("style", pair.style)):
        frames = len(cache(clip, fps)[1])
        if frames < window:
            return f"{clip.path}: {role} clip of {frames} frames is shorter than one style window of {window}"
    return ""


def _pair_record(pair: Pair) -> dict:
    gt = pair.ground_truth
    return {
        "content": str(pair.content.path),
        "style": str(pair.style.path),
        "style_label": pair.style.style,
        "ground_truth": None if gt is None else str(gt.path),
    }


def _select(clips, contents, data_dir):
    if contents is None:
        return list(clips)
    wanted = set(contents)
    known = {c.content for c in clips}
    missing = sorted(wanted - known)
    if missing:
        raise DataError(
            f"{data_dir}: no clips with content {', '.join(missing)} (known: {', '.join(sorted(known))})"
        )
    return [c for c in clips if c.content in wanted]


def _load_pairs(data_dir, pairs, max_pairs, contents, seed, progress):
    from jaxgest.motion.datasets import load_folder

    clips = load_folder(data_dir, progress=progress)
    # Only the content clips are filtered; style (and ground-truth) clips come from the whole dataset.
    chosen = {id(c) for c in _select(clips, contents, data_dir)}
    found = [p for p in make_pairs(clips, pairs, seed=seed) if id(p.content) in chosen]
    if max_pairs is not None and len(found) > max_pairs:
        keep = np.sort(np.random.default_rng(seed).choice(len(found), size=max_pairs, replace=False))
        found = [found[i] for i in keep]
    if not found:
        raise DataError(
            f"{data_dir}: no {pairs} content/style pairs (content clips need a style named "
            f"{' or '.join(NEUTRAL)}, style clips another style)"
        )
    return found


def evaluate(
    workdir,
    data_dir,
    *,
    pairs: str = "intra",
    methods: Sequence[str] = METHODS,
    max_pairs: int | None = None,
    contents: Sequence[str] | None = None,
    seed: int = 0,
    model=None,
    progress: bool = True,
) -> dict:
    """Evaluate style transfer over a dataset's pairs: the paper's Tables 2/3 plus ground-truth errors.

    Loads the model of ``workdir`` (``jaxgest.tgst.api.load_model``; or uses ``model``, any object with
    ``.transfer(content, style, method=...) -> Motion``), builds :func:`make_pairs` of ``data_dir``
    (``contents`` restricts the content clips), transfers every pair with every method and returns::

        {"workdir", "data", "pairs", "num_pairs", "methods": {m: {"content", "style", "gt_content",
         "gt_style", "num_gt", "num_skipped"}}, "per_pair": [{"content", "style", "style_label",
         "ground_truth", "errors": {m: {...}} | "skipped": reason}]}

    where each error is the average over pairs of ``{"mean","worst","w25"}`` (None without pairs).
    Pairs whose content or style clip is shorter than one style window are skipped (not transferred) and
    counted, as are transfers the model rejects with a DataError; a ground truth shorter than one window
    gives no ground-truth errors for that pair.
    References: Kuriyama et al. 2022, §4.3, Tables 2 and 3.
    """
    from tqdm import tqdm

    if not methods:
        raise DataError("evaluate: no methods given")
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise DataError(f"evaluate: unknown method {unknown[0]!r} (choose from {', '.join(METHODS)})")
    if model is None:
        from jaxgest.tgst.api import load_model

        model = load_model(workdir)
    found = _load_pairs(data_dir, pairs, max_pairs, contents, seed, progress)
    cache = _FeatureCache()
    collected = {m: {k: [] for k in ERROR_KEYS} for m in methods}
    skipped = {m: 0 for m in methods}
    per_pair = []
    for pair in tqdm(found, desc=f"evaluate ({pairs})", unit="pair", disable=not progress):
        record = _pair_record(pair)
        record["errors"] = {}
        fps = pair.content.motion.fps  # the result is on the content's rig, frame count and rate
        window = metrics.window_for_fps(fps)
        short = _too_short(pair, cache, fps, window)
        for method in methods:
            if short:
                skipped[method] += 1
                record["errors"][method] = {"skipped": short}
                continue
            try:
                result = model.transfer(pair.content.motion, pair.style.motion, method=method)
                gt = None if pair.ground_truth is None else cache(pair.ground_truth, result.fps)
                if gt is not None and len(gt[1]) < window:
                    gt = None  # ground truth shorter than one window: no ground-truth errors for this pair
                errs = features_errors(
                    clip_features(result, result.fps),
                    cache(pair.content, result.fps),
                    cache(pair.style, result.fps),
                    gt,
                    window=metrics.window_for_fps(result.fps),
                )
            except DataError as e:
                skipped[method] += 1
                record["errors"][method] = {"skipped": str(e)}
                continue
            record["errors"][method] = errs
            for k, v in errs.items():
                collected[method][k].append(v)
        per_pair.append(record)
    summary = {}
    for m in methods:
        summary[m] = {k: _average(collected[m][k]) for k in ERROR_KEYS}
        summary[m]["num_gt"] = len(collected[m]["gt_content"])
        summary[m]["num_evaluated"] = len(collected[m]["content"])
        summary[m]["num_skipped"] = skipped[m]
    return {
        "workdir": str(workdir),
        "data": str(data_dir),
        "pairs": pairs,
        "num_pairs": len(found),
        "methods": summary,
        "per_pair": per_pair,
        "notes": NOTES,
    }


def metric_validity(
    data_dir,
    *,
    pairs: str = "inter",
    max_pairs: int | None = None,
    contents: Sequence[str] | None = None,
    seed: int = 0,
    progress: bool = True,
) -> dict:
    """Table 1: errors of the content clip and of the style clip, each against the referential sample.

    For every pair with a ground-truth clip g (the content performed in the style) that is not the style
    clip itself, the content clip c and the style clip s are each taken as if they were a transfer result:
    row "content" = (E^content(g, c), E^style(c | g)), row "style" = (E^content(g, s), E^style(s | g)),
    averaged over pairs. A valid metric gives a smaller content error in row "content" and a smaller style
    error in row "style". Default ``pairs="inter"``: with one take per content and style (Bandai-Namco,
    synthetic) the intra-scenario style clip *is* the ground truth. Returns ``{"pairs", "num_pairs",
    "rows": {"content": {"content", "style"}, "style": {...}}}``.
    References: Kuriyama et al. 2022, §4.2, Table 1.
    """
    from tqdm import tqdm

    found = [
        p
        for p in _load_pairs(data_dir, pairs, None, contents, seed, progress)
        if p.ground_truth is not None and p.ground_truth is not p.style
    ]
    if max_pairs is not None and len(found) > max_pairs:
        keep = np.sort(np.random.default_rng(seed).choice(len(found), size=max_pairs, replace=False))
        found = [found[i] for i in keep]
    if not found:
        raise DataError(f"{data_dir}: no {pairs} pairs with a ground-truth clip distinct from the style clip")
    cache = _FeatureCache()
    rows = {"content": {"content": [], "style": []}, "style": {"content": [], "style": []}}
    for pair in tqdm(found, desc="metric validity", unit="pair", disable=not progress):
        fps = pair.ground_truth.motion.fps
        window = metrics.window_for_fps(fps)
        g = cache(pair.ground_truth, fps)
        for row, clip in (("content", pair.content), ("style", pair.style)):
            x = cache(clip, fps)
            try:
                ce = metrics.content_error(g[0], x[0])
                se = metrics.style_error(x[1], g[1], window)
            except DataError:
                continue
            rows[row]["content"].append(ce)
            rows[row]["style"].append(se)
    return {
        "data": str(data_dir),
        "pairs": pairs,
        "num_pairs": len(found),
        "rows": {r: {k: _average(v) for k, v in cols.items()} for r, cols in rows.items()},
    }


# --------------------------------------------------------------------------------------------------------
# Report tables

_LABELS = {
    "soft": "Soft swap (ours)",
    "hard": "Hard swap (19)",
    "adain": "AdaIN (17)",
    "avatarnet": "Avatar-net (18)",
}


def _fmt(stats: dict | None) -> list[str]:
    return ["-"] * 3 if stats is None else [f"{stats[k]:.3g}" for k in STATS]


def markdown_table(report: dict) -> str:
    """The paper's Table 2/3 layout (+ ground-truth columns) as markdown, one row per method."""
    head = [
        "Method",
        *(f"content {k}" for k in STATS),
        *(f"style {k}" for k in STATS),
        *(f"gt content {k}" for k in STATS),
        *(f"gt style {k}" for k in STATS),
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for m, s in report["methods"].items():
        cells = [_LABELS.get(m, m)] + [c for k in ERROR_KEYS for c in _fmt(s[k])]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def validity_table(table: dict) -> str:
    """The paper's Table 1 layout as markdown: rows content / style sample, content and style errors."""
    head = ["Samples", *(f"content {k}" for k in STATS), *(f"style {k}" for k in STATS)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row, cols in table["rows"].items():
        cells = [row.capitalize()] + [c for k in ("content", "style") for c in _fmt(cols[k])]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


__all__ = [
    "METHODS",
    "Pair",
    "clip_errors",
    "clip_features",
    "evaluate",
    "features_errors",
    "make_pairs",
    "markdown_table",
    "metric_validity",
    "validity_table",
]
