"""Quantitative evaluation of TGST style transfer (paper 000 §4.2-4.3, Tables 1-3; docs/design.md §5).

* :class:`Protocol` / :data:`PROTOCOLS` -- how clips become metric features: ``authors`` (default, the
  paper tables) or ``world`` (ground-truth checks; the protocol of earlier runs).
* :func:`clip_features` / :func:`clip_errors` -- content error (eqs. 13-14, both hands, exact DTW) and style
  error (eqs. 15-16, arm-joint velocities) of one transferred clip, plus the same two errors against the
  ground-truth clip (the content performed in the target style) where the dataset has one (docs/design.md §5).
* :func:`make_pairs` -- content/style evaluation pairs: intra-scenario, inter-scenario or all.
* :func:`evaluate` -- per-method averages over pairs of mean / worst / w25 (Tables 2 and 3), the controls
  "content as is" and "style as is", and swap diagnostics. Transfers run in-process, bucketed by clip
  length (:class:`BatchedTransfer`), so a whole dataset costs a few compilations.
* :func:`metric_validity` -- Table 1: the content clip and the style clip, each against the referential
  ground-truth sample.
* :func:`swap_diagnostics` -- how the soft swap blends: mean max weight, effective number of blended style
  tokens, fraction of argmax within +-1 token of the query's own index and its chance level.

The protocols and per-clip errors live in :mod:`jaxgest.tgst.protocol`, the batched transfers and swap
diagnostics in :mod:`jaxgest.tgst.batched`, the report tables in :mod:`jaxgest.tgst.tables` (all re-exported
here).

Units: BVH positions of both datasets and of the synthetic data are centimetres; hands are compared in
metres and velocities in metres per second, at the result's frame rate (a clip at another rate is
resampled to it).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence

import numpy as np

from jaxgest import metrics
from jaxgest.runtime.errors import DataError
from jaxgest.tgst import model as tgst_model
from jaxgest.tgst.batched import (DEFAULT_BUCKET, BatchedTransfer, bucket_length,  # noqa: F401  (re-exported)
                                  swap_diagnostics)
from jaxgest.tgst.protocol import (CM_TO_M, PROTOCOLS, Protocol, _joint_indices, _notes, clip_errors,  # noqa: F401
                                   check_style_input, clip_features, features_errors, get_protocol,
                                   style_input_clip, style_reference)
from jaxgest.tgst.tables import (ERROR_KEYS, STATS, diagnostics_table, markdown_table,  # noqa: F401
                                 validity_table)

#: every ``method=`` the model accepts
METHODS = tgst_model.METHODS
#: the four methods of the paper's tables
TRANSFER_METHODS = tgst_model.TRANSFER_METHODS
#: the default of :func:`evaluate`: the paper's four and the coherent swap (not in the paper) beside them
EVALUATE_METHODS = tgst_model.EVALUATE_METHODS
PAIR_MODES = ("intra", "inter", "all")
NEUTRAL = ("normal", "neutral")
CONTROLS = ("content_as_is", "style_as_is")


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


def _subset(items: list, max_pairs: int | None, seed: int) -> list:
    """A seeded random subset of ``max_pairs`` items in their order (None or 0 = all)."""
    if max_pairs is None or max_pairs == 0:
        return items
    if max_pairs < 0:
        raise DataError(f"evaluate: --max-pairs must be >= 0 (0 = all pairs), got {max_pairs}")
    if len(items) <= max_pairs:
        return items
    keep = np.sort(np.random.default_rng(seed).choice(len(items), size=max_pairs, replace=False))
    return [items[i] for i in keep]


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
    ``seed``) in that order (None or 0: all pairs). References: Kuriyama et al. 2022, §4.3 (intra- and
    inter-scenario conditions).
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
    return _subset(pairs, max_pairs, seed)


# --------------------------------------------------------------------------------------------------------
# Evaluation


def _average(results: list) -> dict | None:
    """Average of ``{"mean","worst","w25"}`` dicts (the paper averages each metric over samples)."""
    if not results:
        return None
    return {k: float(np.mean([r[k] for r in results])) for k in STATS}


class _FeatureCache:
    """clip_features of dataset clips, computed once per (clip, fps, protocol, reference)."""

    def __init__(self, protocol: Protocol):
        self.protocol = protocol
        self._cache = {}

    def __call__(self, clip, fps, reference: bool = False):
        key = (id(clip), round(float(fps), 6), reference)
        if key not in self._cache:
            motion = clip.motion if clip.motion.name else clip.motion.replace(name=str(clip.path))
            try:
                value = clip_features(motion, fps, self.protocol, reference=reference)
            except DataError as e:
                value = e
            self._cache[key] = (clip, value)
        value = self._cache[key][1]
        if isinstance(value, DataError):
            raise value
        return value


def _too_short(pair: Pair, cache: _FeatureCache, fps: float, window: int) -> str:
    """Why the pair cannot be evaluated (content or style clip too short for the cut or one style window)."""
    for role, clip, ref in (("content", pair.content, False), ("style", pair.style, True)):
        try:
            frames = len(cache(clip, fps, ref)[1])
        except DataError as e:
            return f"{clip.path}: {role} clip: {e}"
        if frames < window:
            return (f"{clip.path}: {role} clip of {frames} velocity frames ({cache.protocol.label} protocol) is "
                    f"shorter than one style window of {window}")
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
    found = _subset([p for p in make_pairs(clips, pairs, seed=seed) if id(p.content) in chosen], max_pairs, seed)
    if not found:
        raise DataError(
            f"{data_dir}: no {pairs} content/style pairs (content clips need a style named "
            f"{' or '.join(NEUTRAL)}, style clips another style)"
        )
    return found


def _gt_features(pair, cache, fps, window):
    """(plain, reference) features of the pair's ground truth, or (None, None) when it has none or it is
    too short for the protocol / one window."""
    if pair.ground_truth is None:
        return None, None
    try:
        gt, gt_ref = cache(pair.ground_truth, fps), cache(pair.ground_truth, fps, True)
    except DataError:
        return None, None
    if len(gt_ref[1]) < window:
        return None, None
    return gt, gt_ref


def _summarize(collected: dict, skipped: int) -> dict:
    out = {k: _average(collected[k]) for k in ERROR_KEYS}
    out["num_gt"] = len(collected["gt_content"])
    out["num_evaluated"] = len(collected["content"])
    out["num_skipped"] = skipped
    return out


def evaluate(
    workdir,
    data_dir,
    *,
    pairs: str = "intra",
    methods: Sequence[str] | None = None,
    max_pairs: int | None = None,
    contents: Sequence[str] | None = None,
    seed: int = 0,
    model=None,
    progress: bool = True,
    protocol="authors",
    trim_seconds: float | None = None,
    bucket: float = DEFAULT_BUCKET,
    style_input: str = "mirror",
) -> dict:
    """Evaluate style transfer over a dataset's pairs: the paper's Tables 2/3, controls, ground-truth errors.

    Loads the model of ``workdir`` (``jaxgest.tgst.api.load_model``; or uses ``model``: a TGSTModel, or any
    object with ``.transfer(content, style, method=...) -> Motion``, transferred pair by pair), builds
    :func:`make_pairs` of ``data_dir`` (``contents`` restricts the content clips; ``max_pairs`` None or 0 =
    all pairs), transfers every pair with every method (default :data:`EVALUATE_METHODS`: the paper's four and
    the coherent swap) and returns::

        {"workdir", "data", "pairs", "num_pairs", "protocol": {...}, "bucket",
         "methods": {m: {"content", "style", "gt_content", "gt_style", "num_gt", "num_evaluated",
                         "num_skipped", "protocol"}},
         "controls": {"content_as_is" | "style_as_is": {same keys}},
         "swap_diagnostics": {...} | None, "timing": {"wall_s", "cpu_s", "compiled_shapes"},
         "per_pair": [{"content", "style", "style_label", "ground_truth", "errors": {m: {...}} |
                       {"skipped": reason}, "controls": {...}, "swap": {...}}], "notes"}

    where each error is the average over pairs of ``{"mean","worst","w25"}`` (None without pairs), under
    ``protocol`` ("authors" or "world", :data:`PROTOCOLS`; ``trim_seconds`` overrides its cut). Pairs whose
    content or style clip is too short for the cut or one style window are skipped (not transferred) and
    counted, as are transfers the model rejects with a DataError; a ground truth that is too short gives no
    ground-truth errors for that pair. ``bucket``: length-bucket ratio of :class:`BatchedTransfer` (<= 1:
    exact per-pair shapes, one compilation per pair). The controls take the content clip and the style clip
    themselves as the result. ``style_input``: what the model is given for each style clip,
    ``"mirror"`` (default: the clip followed by its mirror, as the authors' evaluator.py, which calls
    ``setup_mirror_motions()`` on its style set, and every user transfer) or ``"as-is"`` (the input of the
    Bandai-Namco-1 results, ``experiments/tgst_bandai``); :func:`jaxgest.tgst.protocol.style_input_clip`.
    Swap diagnostics (:func:`swap_diagnostics`) of the soft swap are averaged over pairs when
    "soft" or "hard" is evaluated with a TGSTModel.
    References: Kuriyama et al. 2022, §4.3, Tables 2 and 3.
    """
    from tqdm import tqdm

    wall0, cpu0 = time.perf_counter(), time.process_time()
    proto = get_protocol(protocol, trim_seconds)
    check_style_input(style_input)
    methods = EVALUATE_METHODS if methods is None else tuple(methods)
    if not methods:
        raise DataError("evaluate: no methods given")
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise DataError(f"evaluate: unknown method {unknown[0]!r} (choose from {', '.join(METHODS)})")
    if model is None:
        from jaxgest.tgst.api import load_model

        model = load_model(workdir)
    found = _load_pairs(data_dir, pairs, max_pairs, contents, seed, progress)
    batched, as_is = None, {}
    if hasattr(model, "body_arrays") and hasattr(model, "to_motion") and hasattr(model, "params"):
        batched, as_is = BatchedTransfer(model, methods, ratio=bucket), {"style_input": "as-is"}
    cache = _FeatureCache(proto)
    given: dict = {}  # id(style clip) -> (the clip, the clip the model is given): one mirror per style clip

    def model_input(pair: Pair) -> Pair:
        if style_input == "as-is":
            return pair
        if id(pair.style) not in given:
            clip = pair.style
            given[id(clip)] = (clip, dataclasses.replace(clip, motion=style_input_clip(clip.motion, style_input,
                                                                                       proto)))
        return Pair(pair.content, given[id(pair.style)][1], pair.ground_truth)

    collected = {m: {k: [] for k in ERROR_KEYS} for m in (*methods, *CONTROLS)}
    skipped = {m: 0 for m in (*methods, *CONTROLS)}
    diags, per_pair = [], []
    for pair in tqdm(found, desc=f"evaluate ({pairs}, {proto.label})", unit="pair", disable=not progress):
        record = _pair_record(pair)
        record["errors"], record["controls"] = {}, {}
        per_pair.append(record)
        fps = pair.content.motion.fps  # the result is on the content's rig, frame count and rate
        window = metrics.window_for_fps(fps)
        short = _too_short(pair, cache, fps, window)
        if short:
            for m in (*methods, *CONTROLS):
                skipped[m] += 1
                (record["controls"] if m in CONTROLS else record["errors"])[m] = {"skipped": short}
            continue
        c_feats, s_ref = cache(pair.content, fps), cache(pair.style, fps, True)
        gt, gt_ref = _gt_features(pair, cache, fps, window)
        # controls: the content clip and the style clip (its plain features) taken as the result
        def score(section: str, name: str, result_feats) -> None:
            """Errors of one result (features, or a callable giving them) into ``record`` and the totals."""
            try:
                feats = result_feats() if callable(result_feats) else result_feats
                errs = features_errors(feats, c_feats, s_ref, gt, window=window, gt_reference_feats=gt_ref,
                                       common=proto.common_length)
            except DataError as e:
                skipped[name] += 1
                record[section][name] = {"skipped": str(e)}
                return
            record[section][name] = errs
            for k, v in errs.items():
                collected[name][k].append(v)

        score("controls", "content_as_is", c_feats)
        score("controls", "style_as_is", lambda: cache(pair.style, fps))
        results, failure, fed = {}, None, None
        try:
            fed = model_input(pair)
            if batched is not None:
                results, diag = batched.run(fed)
                if diag is not None:
                    record["swap"] = diag
                    diags.append(diag)
        except DataError as e:
            failure = str(e)
        for method in methods:
            def transferred(method=method):
                if failure is not None:
                    raise DataError(failure)
                result = results.get(method)
                if result is None:  # the clip the batched path is given, as is (a TGSTModel would mirror it
                    # again by default; any other model is given the same clip)
                    result = model.transfer(pair.content.motion, fed.style.motion, method=method, **as_is)
                return clip_features(result, fps, proto)

            score("errors", method, transferred)
    label = proto.label
    summary = {m: dict(_summarize(collected[m], skipped[m]), protocol=label) for m in methods}
    controls = {m: dict(_summarize(collected[m], skipped[m]), protocol=label) for m in CONTROLS}
    swap = None
    if diags:
        swap = {k: float(np.mean([d[k] for d in diags])) for k in diags[0] if k not in ("num_queries", "num_style")}
        swap["num_pairs"] = len(diags)
        swap["method"] = "soft swap weights (eq. 4)"
    return {
        "workdir": str(workdir),
        "data": str(data_dir),
        "pairs": pairs,
        "num_pairs": len(found),
        "protocol": proto.describe(),
        "style_input": style_input,
        "bucket": None if batched is None else (bucket if bucket > 1 else "exact"),
        "methods": summary,
        "controls": controls,
        "swap_diagnostics": swap,
        "timing": {"wall_s": time.perf_counter() - wall0, "cpu_s": time.process_time() - cpu0,
                   "compiled_shapes": None if batched is None else len(batched.shapes)},
        "per_pair": per_pair,
        "notes": _notes(proto),
    }


def metric_validity(
    data_dir,
    *,
    pairs: str = "inter",
    max_pairs: int | None = None,
    contents: Sequence[str] | None = None,
    seed: int = 0,
    progress: bool = True,
    protocol="authors",
    trim_seconds: float | None = None,
) -> dict:
    """Table 1: errors of the content clip and of the style clip, each against the referential sample.

    For every pair with a ground-truth clip g (the content performed in the style) that is not the style
    clip itself, the content clip c and the style clip s are each taken as if they were a transfer result:
    row "content" = (E^content(g, c), E^style(c | g)), row "style" = (E^content(g, s), E^style(s | g)),
    averaged over pairs, under ``protocol`` (under "authors" g's style reference is g + its mirror, as for
    any style reference, and each sample is cut to a common length with g, as the authors' evaluator cuts
    content and transfer). A valid metric gives a smaller content error in row "content" and a smaller style
    error in row "style". Default ``pairs="inter"``: with one take per content and style (Bandai-Namco,
    synthetic) the intra-scenario style clip *is* the ground truth. Pairs with a clip too short for the
    protocol are left out and counted. Returns ``{"pairs", "num_pairs", "num_evaluated", "protocol",
    "rows": {"content": {"content", "style"}, "style": {...}}}``.
    References: Kuriyama et al. 2022, §4.2, Table 1.
    """
    from tqdm import tqdm

    proto = get_protocol(protocol, trim_seconds)
    found = [
        p
        for p in _load_pairs(data_dir, pairs, None, contents, seed, progress)
        if p.ground_truth is not None and p.ground_truth is not p.style
    ]
    found = _subset(found, max_pairs, seed)
    if not found:
        raise DataError(f"{data_dir}: no {pairs} pairs with a ground-truth clip distinct from the style clip")
    cache = _FeatureCache(proto)
    rows = {"content": {"content": [], "style": []}, "style": {"content": [], "style": []}}
    for pair in tqdm(found, desc=f"metric validity ({proto.label})", unit="pair", disable=not progress):
        fps = pair.ground_truth.motion.fps
        window = metrics.window_for_fps(fps)
        try:
            g, g_ref = cache(pair.ground_truth, fps), cache(pair.ground_truth, fps, True)
            xs = [cache(clip, fps) for clip in (pair.content, pair.style)]
            results = []
            for x in xs:  # each sample taken as a result against g (cut to a common length with it)
                e = features_errors(x, g, g_ref, window=window, common=proto.common_length)
                results.append((e["content"], e["style"]))
        except DataError:
            continue
        for row, (ce, se) in zip(("content", "style"), results):
            rows[row]["content"].append(ce)
            rows[row]["style"].append(se)
    return {
        "data": str(data_dir),
        "pairs": pairs,
        "num_pairs": len(found),
        "num_evaluated": len(rows["content"]["content"]),
        "protocol": proto.label,
        "rows": {r: {k: _average(v) for k, v in cols.items()} for r, cols in rows.items()},
    }


__all__ = [
    "METHODS",
    "PROTOCOLS",
    "EVALUATE_METHODS",
    "TRANSFER_METHODS",
    "BatchedTransfer",
    "Pair",
    "Protocol",
    "bucket_length",
    "clip_errors",
    "clip_features",
    "diagnostics_table",
    "evaluate",
    "features_errors",
    "get_protocol",
    "make_pairs",
    "markdown_table",
    "metric_validity",
    "style_reference",
    "swap_diagnostics",
    "validity_table",
]
