"""Multi-take TGST evaluation, the scoring half (the splits and pairs are :mod:`jaxgest.tgst.multitake`): every
method, input variant and control on every :class:`~jaxgest.tgst.multitake.TakePair` against its ground-truth
takes (:func:`evaluate_pairs`), the controls' pieces (:func:`collage_bound`, :func:`hands_oracle`,
:func:`token_collage`, :func:`pca_round_trip`), the arm-speed round trip (:func:`round_trip_speeds`) and
Table 1's data-only cross-form check (:func:`cross_validity`). docs/design.md §5 "Multi-take data".
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from jaxgest.runtime.errors import DataError
from jaxgest.tgst.multitake import SPLITS, TakePair, condition_of, split_by_take, take_of  # noqa: F401


# --------------------------------------------------------------------------------------------------------
# Errors of one pair: methods, input variants and controls

#: model-input variants of the exemplar: as is (the authors' evaluator) / followed by its mirror (0.5 s blend)
VARIANTS = ("as_is", "mirror")
ERRORS = ("content", "style", "gt_content", "gt_style")


def multitake_protocol(trim_seconds: float = 0.3):
    """The authors' protocol with a 0.3 s cut (Bandai-Namco-2 clips are 1.2-8.5 s; 1 s would empty the
    shortest)."""
    from jaxgest.tgst.protocol import get_protocol

    return get_protocol("authors", trim_seconds)


def window_frames(fps: float, theta_at_60: int = 64) -> int:
    """Style window at ``fps``: 64 frames at 60 fps (32 at 30 fps, ~1.07 s). The 128-frame window of docs/design.md §5
    (2.1 s) is longer than every normal / active / feminine / youthful raise-up clip after the cut."""
    from jaxgest import metrics

    return metrics.window_for_fps(fps, theta_at_60)


class FeatureCache:
    """:func:`jaxgest.tgst.protocol.clip_features` of clips or motions at one rate, computed once per
    (object, reference)."""

    def __init__(self, protocol, fps: float):
        self.protocol, self.fps, self._cache = protocol, float(fps), {}

    def __call__(self, item, reference: bool = False):
        from jaxgest.tgst.protocol import clip_features

        key = (id(item), reference)
        if key not in self._cache:
            motion = getattr(item, "motion", item)
            if hasattr(item, "path") and not motion.name:
                motion = motion.replace(name=str(item.path))
            self._cache[key] = (item, clip_features(motion, self.fps, self.protocol, reference=reference))
        return self._cache[key][1]


def errors_against(result, content, exemplar_ref, gts, *, window: int, common: bool = True) -> dict:
    """Mean errors of one result (features) against the content clip, the exemplar's style reference and the
    ground-truth takes (``gts``: ``[(plain, reference)]`` features): ``{"content", "style", "gt_content",
    "gt_style"}`` (floats; the eq. 13 / 15 means; ground-truth errors averaged over the takes; None
    without a take). Result and content (or ground truth) are cut to a common length (``common``).
    References: Kuriyama et al. 2022, eqs. 13-16; docs/design.md §5 (ground truth = every other take, averaged).
    """
    import numpy as np

    from jaxgest.tgst.protocol import features_errors

    e = features_errors(result, content, exemplar_ref, window=window, common=common)
    out = {"content": e["content"]["mean"], "style": e["style"]["mean"], "gt_content": None, "gt_style": None}
    per = [features_errors(result, content, exemplar_ref, g, window=window, gt_reference_feats=g_ref,
                           common=common) for g, g_ref in gts]
    if per:
        out["gt_content"] = float(np.mean([p["gt_content"]["mean"] for p in per]))
        out["gt_style"] = float(np.mean([p["gt_style"]["mean"] for p in per]))
    return out


def collage_bound(target_hands, pool_hands) -> float:
    """Lower bound of the content error (metres) of any collage of ``pool_hands`` frames against
    ``target_hands``: the mean over target frames of the distance to the nearest pool frame (each DTW-aligned
    pair costs at least it; only the path's uneven weighting can go below). References: eqs. 13-14."""
    import numpy as np

    t, p = np.asarray(target_hands, np.float64), np.asarray(pool_hands, np.float64)
    d2 = (t * t).sum(1)[:, None] + (p * p).sum(1)[None] - 2 * t @ p.T
    return float(np.sqrt(np.maximum(d2.min(1), 0)).mean())


def hands_oracle(model, content_motion, style_motion):
    """The content performed with the style tokens an oracle picks: each content token (16 frames at the
    model rate) -> the style token whose root-local hand positions are nearest to its own, decoded as a
    transfer (same encoder, tokens, cross-fade, decoder). What a perfect content similarity could reach with
    this exemplar's tokens. Returns a Motion on the content's rig. (Diagnostic, not in the paper.)"""
    return token_collage(model, content_motion, style_motion, order="nearest")


#: how :func:`token_collage` orders the style tokens it picks
COLLAGE_ORDERS = ("nearest", "constant_rate")


def token_collage(model, content_motion, style_motion, order: str = "nearest"):
    """The content decoded from style tokens chosen by hand positions (the content metric's own features).

    Each content token (16 frames at the model rate) is compared with every style token by the root-local
    hand positions of their frames. ``order="nearest"``: each takes its nearest style token on its own (the
    hands oracle); ``"constant_rate"``: all take the tokens along the one constant-rate path through the
    style clip with the smallest mean distance (:func:`jaxgest.tgst.swap.constant_rate_path`), i.e. the
    style's frames in their own order, re-timed at one rate. Decoded as a transfer (same encoder, tokens,
    cross-fade, decoder); returns a Motion on the content's rig. (Diagnostic, not in the paper.)
    References: Kuriyama et al. 2022, eqs. 1 and 4 (tokens, the swap whose choice this replaces).
    """
    import jax.numpy as jnp
    import numpy as np

    from jaxgest import metrics
    from jaxgest.motion import body, kinematics
    from jaxgest.motion.datasets import resample_motion
    from jaxgest.tgst import model as M
    from jaxgest.tgst.swap import constant_rate_path
    from jaxgest.tgst.tokens import detokenize, tokenize

    if order not in COLLAGE_ORDERS:
        raise ValueError(f"token_collage: unknown order {order!r} (expected one of {COLLAGE_ORDERS})")
    cfg, params = model.cfg, model.params
    red, w, h, lead = cfg.autoencoder.time_reduction, cfg.token_width, cfg.token_stride, cfg.edge_frames
    cu, su = model.body_arrays(content_motion, "content"), model.body_arrays(style_motion, "style")
    zc, zs, _, _ = M.encode_pair(params["autoencoder"], jnp.asarray(cu)[None], jnp.asarray(su)[None], cfg=cfg)
    tc, ts = np.asarray(tokenize(zc, w, h)[0]), np.asarray(tokenize(zs, w, h)[0])

    def hands(m):
        m = resample_motion(m, cfg.fps)
        return metrics.hands_metres(kinematics.root_local_positions(m), body.joint_indices(m.skeleton, body.HANDS))

    def windows(x, starts, length):
        lo, hi = max(0, -min(starts)), max(0, max(starts) + length - len(x))
        xp = np.pad(x, ((lo, hi), (0, 0)), mode="edge")
        return np.stack([xp[s + lo:s + lo + length].reshape(-1) for s in starts])

    hc = windows(hands(content_motion), [n * h * red - lead for n in range(len(tc))], w * red)
    hs = windows(hands(style_motion), [m * h * red for m in range(len(ts))], w * red)
    d2 = (hc * hc).sum(1)[:, None] + (hs * hs).sum(1)[None] - 2 * hc @ hs.T
    if order == "nearest":
        idx = np.argmin(d2, 1)
    else:
        idx = np.asarray(constant_rate_path(-jnp.sqrt(jnp.maximum(jnp.asarray(d2), 0.0))[None]))[0]
    z = detokenize(jnp.asarray(ts[idx])[None], zc.shape[1], w, h)
    up, lo = M.decode(params["autoencoder"], z, cfg=cfg)
    up, lo = M.trim_clip(up, len(cu), cfg=cfg), M.trim_clip(lo, len(cu), cfg=cfg)
    return model.to_motion(np.asarray(up[0]), np.asarray(lo[0]), content_motion)


def pca_round_trip(model, pca: dict, content_motion):
    """The content through block PCA of its upper-body exp-maps (16 numbers per 4 frames: the autoencoder's
    latent budget; :func:`jaxgest.tgst.baselines.block_pca_reconstruct`), lower body as is. A Motion."""
    from jaxgest.tgst.baselines import block_pca_reconstruct
    from jaxgest.tgst.data import motion_to_arrays

    up, lo = motion_to_arrays(content_motion, model.cfg.fps)
    return model.to_motion(block_pca_reconstruct(pca, up), lo, content_motion)


def fit_pca(model, clips, components: int = 16):
    """Block PCA (:func:`jaxgest.tgst.baselines.block_pca_fit`) of the upper-body exp-maps of ``clips`` at the
    model rate (the training takes)."""
    from jaxgest.tgst.baselines import block_pca_fit
    from jaxgest.tgst.data import motion_to_arrays

    return block_pca_fit([motion_to_arrays(c.motion, model.cfg.fps)[0] for c in clips], components=components)


def _exemplar_input(exemplar, variant: str, protocol):
    """The style clip the model is given (:data:`VARIANTS`): the exemplar as is, or the exemplar + its mirror;
    :func:`jaxgest.tgst.protocol.style_input_clip`, the function of every user transfer."""
    from jaxgest.motion.datasets import Clip
    from jaxgest.tgst.protocol import style_input_clip

    if variant == "as_is":
        return exemplar
    return Clip(style_input_clip(exemplar.motion, "mirror", protocol), exemplar.content, exemplar.style,
                exemplar.path)


@dataclasses.dataclass(frozen=True)
class _Run:
    """What :meth:`jaxgest.tgst.batched.BatchedTransfer.run` reads of a pair."""

    content: object
    style: object


def evaluate_pairs(model, pairs: Sequence, *, protocol=None, methods: Sequence[str] = ("soft", "hard", "adain",
                   "avatarnet"), pca: dict | None = None, oracle_every: int = 1, variants: Sequence[str] = VARIANTS,
                   controls: bool = True, progress: bool = False) -> dict:
    """Errors of every method, input variant and control on every :class:`TakePair`.

    Returns ``{"protocol", "window", "pairs": [{"condition", "content", "exemplar", "style",
    "ground_truths", "swap|{variant}": soft-swap diagnostics (:func:`jaxgest.tgst.batched.swap_diagnostics`,
    with a soft or hard method), "rows": {row: {"content", "style", "gt_content", "gt_style"}} | "skipped":
    why}]}``,
    rows: ``"{method}|{variant}"`` (variants :data:`VARIANTS`), ``"autoencoder"`` (content round trip),
    ``"pca16"`` (with ``pca``), ``"oracle_hands|{variant}"`` and ``"oracle_rate|{variant}"``
    (:func:`token_collage` nearest / constant rate, on every ``oracle_every``-th pair, 0 = none: they run
    eagerly, ~2 s a pair), ``"content_as_is"``,
    ``"style_as_is"``, ``"gt_take"`` (each ground-truth take as the result, its gt columns against the other
    takes = the take-to-take floor; averaged over the takes; only with >= 2 takes), ``"collage|{variant}"``
    (:func:`collage_bound` of the exemplar's frames, without / with its mirrored frames: content and
    gt_content only). Errors: means (eqs. 13 / 15) under ``protocol`` (default :func:`multitake_protocol`),
    window :func:`window_frames`. ``variants`` restricts the input variants; ``controls=False`` leaves out
    the rows that do not depend on the model (content / style as is, gt_take, collage). A pair whose content
    or exemplar is too short is skipped with the reason.
    References: Kuriyama et al. 2022, §4.2-4.3, eqs. 13-16; docs/design.md §5.
    """
    import numpy as np
    from tqdm import tqdm

    from jaxgest.tgst.batched import BatchedTransfer
    from jaxgest.tgst.data import mirror_motion
    from jaxgest.tgst.protocol import clip_features

    proto = protocol or multitake_protocol()
    methods = tuple(methods)
    batched = BatchedTransfer(model, (*methods, "autoencoder"), diagnostics=True)
    caches, inputs, records, pca_feats, ae_feats = {}, {}, [], {}, {}
    for index, pair in enumerate(tqdm(pairs, desc="multi-take pairs", unit="pair", disable=not progress)):
        fps = pair.content.motion.fps
        feats = caches.setdefault(fps, FeatureCache(proto, fps))
        window = window_frames(fps)
        rec = {"condition": pair.condition, "content": str(pair.content.path), "exemplar": str(pair.exemplar.path),
               "style": pair.style, "ground_truths": [str(g.path) for g in pair.ground_truths]}
        records.append(rec)
        try:
            c, e_ref = feats(pair.content), feats(pair.exemplar, True)
            gts = [(feats(g), feats(g, True)) for g in pair.ground_truths]
            if len(c[1]) < window:
                raise DataError(f"{pair.content.path}: content clip of {len(c[1])} velocity frames is shorter "
                                f"than one style window of {window}")
        except DataError as err:
            rec["skipped"] = str(err)
            continue
        rows = {}

        def plain(motion):
            return clip_features(motion, fps, proto)

        def score(name, result, gt_list=gts):
            try:
                rows[name] = errors_against(result() if callable(result) else result, c, e_ref, gt_list,
                                            window=window, common=proto.common_length)
            except DataError as err:
                rows[name] = {"skipped": str(err)}

        for variant in variants:
            key = (id(pair.exemplar), variant)
            if key not in inputs:
                inputs[key] = (pair.exemplar, _exemplar_input(pair.exemplar, variant, proto))
            style_in = inputs[key][1]
            outs, diag = batched.run(_Run(pair.content, style_in))
            if diag is not None:  # how the soft swap's weights (and the hard swap's argmax) move
                rec[f"swap|{variant}"] = diag
            for m in methods:
                score(f"{m}|{variant}", lambda m=m: plain(outs[m]))
            if id(pair.content) not in ae_feats:  # the round trip ignores the style: once per content clip
                ae_feats[id(pair.content)] = (pair.content, plain(outs["autoencoder"]))
            score("autoencoder", ae_feats[id(pair.content)][1])
            if oracle_every and index % oracle_every == 0:
                score(f"oracle_hands|{variant}",
                      lambda: plain(hands_oracle(model, pair.content.motion, style_in.motion)))
                score(f"oracle_rate|{variant}", lambda: plain(
                    token_collage(model, pair.content.motion, style_in.motion, order="constant_rate")))
        if pca is not None:
            key = id(pair.content)
            if key not in pca_feats:
                pca_feats[key] = (pair.content, plain(pca_round_trip(model, pca, pair.content.motion)))
            score("pca16", pca_feats[key][1])
        if not controls:
            rec["rows"] = rows
            continue
        score("content_as_is", c)
        score("style_as_is", lambda: feats(pair.exemplar))
        if len(gts) >= 2:
            per = []
            for i, g in enumerate(pair.ground_truths):
                others = [x for j, x in enumerate(gts) if j != i]
                try:
                    per.append(errors_against(feats(g), c, e_ref, others, window=window,
                                              common=proto.common_length))
                except DataError:
                    continue
            if per:
                rows["gt_take"] = {k: float(np.mean([p[k] for p in per])) for k in ERRORS}
        own = feats(pair.exemplar)[0]
        pools = {"as_is": own, "mirror": np.concatenate([own, plain(mirror_motion(pair.exemplar.motion))[0]])}
        for variant, pool in pools.items():
            rows[f"collage|{variant}"] = {
                "content": collage_bound(c[0], pool), "style": None, "gt_style": None,
                "gt_content": float(np.mean([collage_bound(g[0], pool) for g, _ in gts])) if gts else None}
        rec["rows"] = rows
    return {"protocol": proto.describe(), "window": {"theta_at_60": 64}, "pairs": records}


# --------------------------------------------------------------------------------------------------------
# Data-only checks: Table 1 in the cross form, arm speeds


def arm_speed(arm_velocities) -> float:
    """Mean arm-joint speed (m/s) of :func:`jaxgest.tgst.protocol.clip_features` velocities ``(F, 24)``."""
    import numpy as np

    v = np.asarray(arm_velocities, np.float64)
    return float(np.linalg.norm(v.reshape(len(v), -1, 3), axis=-1).mean())


def round_trip_speeds(model, clips: Sequence, protocol=None) -> list:
    """Per clip ``{"clip", "cell", "input", "output"}``: mean arm speed (:func:`arm_speed`, m/s) of the clip
    and of its autoencoder round trip, under ``protocol`` (default :func:`multitake_protocol`)."""
    from jaxgest.tgst.protocol import clip_features

    from jaxgest.tgst.batched import BatchedTransfer

    proto = protocol or multitake_protocol()
    batched = BatchedTransfer(model, ("autoencoder",), diagnostics=False)  # length buckets: few compilations
    out = []
    for c in clips:
        rt = batched.run(_Run(c, c))[0]["autoencoder"]
        out.append({"clip": str(c.path), "cell": f"{c.content}/{c.style}",
                    "input": arm_speed(clip_features(c.motion, c.motion.fps, proto)[1]),
                    "output": arm_speed(clip_features(rt, c.motion.fps, proto)[1])})
    return out


def cross_validity(clips: Sequence, takes: Sequence[int] = SPLITS["test"], protocol=None,
                   progress: bool = False) -> list:
    """Table 1 in the cross form (docs/design.md §5): for every reference g (a take of content X in style s) and every
    other style s' and other content Y, the *content sample* (X in s', same take number) and the *style
    sample* (Y in s, same take number), each scored as if it were a transfer against g (content error vs g;
    style error vs g + its mirror; cut to a common length with g). A valid content metric scores the content
    sample lower, a valid style metric the style sample. Returns per triple ``{"condition"`` (of Y against
    X: inter-mirror / inter-other), ``"reference", "content_sample", "style_sample", "content": [content
    sample's, style sample's] content errors, "style": [content sample's, style sample's] style errors}``.
    References: Kuriyama et al. 2022, §4.2, Table 1.
    """
    from tqdm import tqdm

    from jaxgest.tgst.protocol import features_errors

    proto = protocol or multitake_protocol()
    test = split_by_take(clips, takes)
    cell = {(c.content, c.style, take_of(c)): c for c in test}
    contents, styles = sorted({c.content for c in test}), sorted({c.style for c in test})
    caches, out = {}, []
    for g in tqdm(sorted(test, key=lambda c: str(c.path)), desc="cross validity", disable=not progress):
        fps = g.motion.fps
        feats = caches.setdefault(fps, FeatureCache(proto, fps))
        window = window_frames(fps)
        t = take_of(g)
        try:
            gf, gr = feats(g), feats(g, True)
        except DataError:
            continue
        for s2 in styles:
            for y in contents:
                if s2 == g.style or y == g.content:
                    continue
                cs, ss = cell.get((g.content, s2, t)), cell.get((y, g.style, t))
                if cs is None or ss is None:
                    continue
                try:
                    ec = features_errors(feats(cs), gf, gr, window=window, common=proto.common_length)
                    es = features_errors(feats(ss), gf, gr, window=window, common=proto.common_length)
                except DataError:
                    continue
                out.append({"condition": condition_of(g.content, y), "reference": str(g.path),
                            "content_sample": str(cs.path), "style_sample": str(ss.path),
                            "content": [ec["content"]["mean"], es["content"]["mean"]],
                            "style": [ec["style"]["mean"], es["style"]["mean"]]})
    return out
