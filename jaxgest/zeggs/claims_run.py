"""Running the claims of :mod:`jaxgest.zeggs.claims` on a trained model: generation for the held-out items,
real speech, the held-out datasets, the whole evaluation (:func:`evaluate_claims`, :func:`run`, what
``jaxgest zeggs evaluate --claims`` calls) and its markdown report. The measures and their thresholds live in
:mod:`jaxgest.zeggs.claims`.

References: Ghorbani et al. 2023, §5.1, §5.3; docs/design.md §5.
"""

from __future__ import annotations

import collections
import pathlib
from collections.abc import Callable, Sequence

import numpy as np

from jaxgest import metrics
from jaxgest.runtime.errors import DataError
from jaxgest.zeggs.claims import (FAR_ABOVE_MM, REALISM_MAX, SPEECH_STYLES, STYLE_RATIO, SUBSTITUTES,
                                  ZERO_SHOT_RATIO, appropriateness, beat_align, claim_items,
                                  clip_accuracy, hand_speeds, interval, motion_beats, realism, style_embeddings,
                                  style_portrayal, substitute_motion, zero_shot)
from jaxgest.zeggs.style_judge import STD_FLOOR_FRACTION, StyleClassifier


def generate_items(model, items, *, seed: int = 0, progress: bool = False, style_scale: float = 1.0) -> list:
    """The model's motion for every item: its clip's speech in the style of its example (its embedding times
    ``style_scale``: the paper's scaling of style embeddings, ``weights=[style_scale]``)."""
    from tqdm.auto import tqdm

    from jaxgest.motion.datasets import load_clip_audio

    out = []
    for it in tqdm(items, desc="claims: generate", disable=not progress, leave=False):
        audio, sr = load_clip_audio(it.clip)
        out.append(model.generate(audio, [it.example.motion], weights=[style_scale], sr=sr, seed=seed,
                                  name=f"{it.clip.path.stem}_gen"))
    return out


def speech_segments(path, segment_s: float) -> list[tuple]:
    """``(samples, sr, start_s)`` of consecutive ``segment_s``-second segments of a speech file (a last
    segment shorter than half of it is dropped; a file shorter than that is one segment)."""
    from jaxgest.audio import load_audio

    y, sr = load_audio(path)
    n = int(round(segment_s * sr))
    if n < 1:
        raise DataError(f"{path}: segment length {segment_s} s is too short")
    segs = [(y[s:s + n], sr, s / sr) for s in range(0, len(y), n) if len(y[s:s + n]) >= n // 2]
    if not segs:
        segs = [(y, sr, 0.0)]
    return segs


def real_speech(model, wavs, train_clips, *, styles: Sequence[str] = SPEECH_STYLES, segment_s: float = 10.0,
                seed: int = 0, classifier: StyleClassifier | None = None, progress: bool = False,
                style_scale: float = 1.0) -> dict:
    """Criterion 5: gestures generated from real speech files in each of ``styles`` (the example: the first
    training clip of the style, by content), per ``segment_s``-second segment. Per style: BeatAlign of the
    generated motion against the segment's onsets, of MM (real training clips of the style, cycled, scored
    against the same onsets) and of the generated motion against shifted onsets, with paired differences and
    intervals over segments; and the classifier's share of generated windows recognised as the style (with
    the counts of every predicted style). ``holds`` per style: lower 95 % bound of generated - MM > 0."""
    from tqdm.auto import tqdm

    train = sorted(train_clips, key=lambda c: (str(c.content), str(c.path)))
    classifier = classifier or StyleClassifier.fit(train)
    segments = []
    for w in wavs:
        if not pathlib.Path(w).is_file():
            raise DataError(f"{w}: no such speech file")
        segments += [(str(w), *s) for s in speech_segments(w, segment_s)]
    out = {"files": [str(w) for w in wavs], "segments": len(segments), "segment_s": segment_s, "styles": {}}
    missing = [s for s in styles if s not in {c.style for c in train}]
    if missing:
        raise DataError(f"real speech: no training clip of the style(s) {', '.join(missing)}")
    for style in styles:
        pool = [c for c in train if c.style == style]
        rows, motions = [], []
        for i, (w, y, sr, t0) in enumerate(tqdm(segments, desc=f"claims: speech ({style})", disable=not progress,
                                              leave=False)):
            g = model.generate(y, [pool[0].motion], weights=[style_scale], sr=sr, seed=seed,
                               name=f"speech_{style}_{i}")
            onsets = metrics.onset_times(y, sr)
            duration = len(y) / sr
            gb = motion_beats(g)
            rows.append({"file": w, "start_s": t0, "generated": beat_align(g, onsets),
                         "mm": beat_align(pool[i % len(pool)].motion, onsets, max_s=duration),
                         "shuffled": metrics.shuffled_beat_alignment(gb, onsets, duration, seed=seed)
                         if len(gb) else float("nan")})
            motions.append(g)
        units = [f"segment-{i}" for i in range(len(rows))]  # segments are the units
        col = {k: np.array([r[k] for r in rows]) for k in ("generated", "mm", "shuffled")}
        res = {k: interval(v, units, "segment") for k, v in col.items()}
        res["generated_minus_mm"] = interval(col["generated"] - col["mm"], units, "segment")
        res["generated_minus_shuffled"] = interval(col["generated"] - col["shuffled"], units, "segment")
        preds = [p for ps in classifier.predict(motions) for p in ps]
        res["recognised"] = clip_accuracy(preds, style)
        res["predicted_counts"] = dict(collections.Counter(preds))
        res["example"] = str(pool[0].path)
        res["holds"] = bool(res["generated_minus_mm"]["low"] > 0)
        out["styles"][style] = res
    out["rule"] = "per style: lower 95 % bound over segments of (generated - MM) > 0"
    return out


def evaluate_claims(model, train_clips, datasets, *, seed: int = 0, substitute: str | None = None,
                    exclude_styles: Sequence[str] = (), progress: bool = False,
                    generate: Callable | None = None, style_scale: float = 1.0) -> dict:
    """Criteria 1, 3 and 4 (and 2 for every style in ``exclude_styles``, the styles the model never saw)
    on held-out ``datasets`` (``(name, clips)`` pairs); ``train_clips``: the real training-script clips
    (classifier, examples, MM). ``substitute`` (:data:`SUBSTITUTES`) replaces the generated motion by real
    motion (a check of the evaluation; ``model`` may then be None); ``generate(items) -> motions``
    replaces the model's generation (tests); ``style_scale`` scales the example's style embedding."""
    train_clips = list(train_clips)
    items = claim_items(train_clips, datasets)
    if substitute is not None:
        motions = [substitute_motion(it, substitute) for it in items]
    elif generate is not None:
        motions = list(generate(items))
    else:
        if model is None:
            raise DataError("claims: no model and no substitute")
        motions = generate_items(model, items, seed=seed, progress=progress, style_scale=style_scale)
    cache = {}  # motion features, computed once per motion within this evaluation
    classifier = StyleClassifier.fit(train_clips, cache)
    portrayal = style_portrayal(classifier, items, motions, cache)
    out = {"source": substitute or "generated", "datasets": sorted({it.dataset for it in items}, key=str),
           "clips": len(items), "style_portrayal": portrayal, "realism": realism(items, motions, train_clips, cache),
           "appropriateness": appropriateness(items, motions, seed=seed),
           "hand_speeds": hand_speeds(items, motions)}
    if exclude_styles:
        emb = None
        if model is not None and substitute is None:
            emb = style_embeddings(model, [it.clip for it in items])
        out["zero_shot"] = {s: zero_shot(portrayal, s, emb) for s in exclude_styles}
    return out


def heldout_datasets(dirs=(), seeds: int = 0, *, tmp_dir=None, progress: bool = False) -> list:
    """``(name, clips)`` of each held-out folder of ``dirs`` (named by its path), then of the built-in
    synthetic data of seeds 1..``seeds`` written into ``tmp_dir`` (named ``synth-seed-K``)."""
    from jaxgest.motion.datasets import load_folder
    from jaxgest.motion.synthetic.dataset import write_dataset

    out = []
    for d in dirs or ():
        if not pathlib.Path(d).is_dir():
            raise DataError(f"{d}: no such held-out data folder")
        clips = [c for c in load_folder(d) if c.audio is not None]
        if not clips:
            raise DataError(f"{d}: no held-out clip with audio")
        out.append((str(d), clips))
    if seeds < 0:
        raise DataError(f"--heldout-seeds must be >= 0, got {seeds}")
    for k in range(1, seeds + 1):
        folder = pathlib.Path(tmp_dir) / f"seed{k}"
        write_dataset(folder, seed=k, progress=False)
        out.append((f"synth-seed-{k}", load_folder(folder)))
    if len({n for n, _ in out}) != len(out):
        raise DataError("claims: the same held-out folder is named twice")
    return out


def _ci(s: dict) -> str:
    return f"{s['mean']:.3f} [{s['low']:.3f}, {s['high']:.3f}]"


def _verdict(ok) -> str:
    return "**holds**" if ok else "**does not hold**"


def markdown(result: dict) -> str:
    """Markdown tables of :func:`evaluate_claims` / :func:`real_speech` results (``result`` may hold
    ``claims`` and ``real_speech``), GT and MM beside the model."""
    lines = []
    c = result.get("claims")
    if c:
        sp, re_, ap = c["style_portrayal"], c["realism"], c["appropriateness"]
        unit = sp["generated"]["unit"]
        lines += [f"Claims on {c['clips']} held-out clips of {len(c['datasets'])} dataset(s), motion: {c['source']}; "
                  f"95 % intervals over {unit}s.", "",
                  "| claim | model | GT | MM | verdict |", "|---|---:|---:|---:|---|",
                  f"| 1. style portrayal: classifier accuracy | {_ci(sp['generated'])} | {_ci(sp['gt'])} | "
                  f"{_ci(sp['mm'])} | {_verdict(sp['holds'])} ({sp['rule']}; ratio to GT "
                  f"{sp['ratio_to_gt'] if sp['ratio_to_gt'] is None else round(sp['ratio_to_gt'], 3)}) |",
                  f"| 3. realism: Fréchet / median real other-script (geometric mean) | {re_['geometric_mean_ratio']:.3f} "
                  f"[{re_['ratio_low']:.3f}, {re_['ratio_high']:.3f}] | 0 | 1 (by definition) | "
                  f"{_verdict(re_['holds'])} ({re_['rule']}) |",
                  f"| 4. appropriateness: BeatAlign vs the speech | {_ci(ap['generated'])} | {_ci(ap['gt'])} | "
                  f"{_ci(ap['mm'])} | {_verdict(ap['holds'])} ({ap['rule']}) |",
                  f"| 4. generated - MM / - shuffled ({_ci(ap['shuffled'])}) | {_ci(ap['generated_minus_mm'])} / "
                  f"{_ci(ap['generated_minus_shuffled'])} | GT - MM {_ci(ap['gt_minus_mm'])} | | |", "",
                  "| style | generated | GT | MM | ratio | most predicted (generated) |", "|---|---:|---:|---:|---:|---|"]
        for s, p in sp["per_style"].items():
            top = max(sp["confusion"][s].items(), key=lambda kv: kv[1])[0] if sp["confusion"][s] else ""
            r = "" if p["ratio"] is None else f"{p['ratio']:.2f}"
            lines.append(f"| {s} | {p['generated']:.3f} | {p['gt']:.3f} | {p['mm']:.3f} | {r} | {top} |")
        lines.append("")
        hs = c.get("hand_speeds")
        if hs:  # diagnostic of criterion 1: damping and handedness
            lines += [f"Hand speed generated / GT (diagnostic): {_ci(hs['ratio'])}; left hand's share of the speed: "
                      + ", ".join(f"{k} {v:.2f}" for k, v in hs["left_share"].items()), "",
                      "| style | hand speed L / R: generated | GT | example | generated / GT |", "|---|---:|---:|---:|---:|"]
            for s, d in hs["per_style"].items():
                r = "" if d["ratio"] is None else f"{d['ratio']:.2f}"
                lines.append(f"| {s} | " + " | ".join(f"{d[k]['left']:.3g} / {d[k]['right']:.3g}"
                                                    for k in ("generated", "gt", "example")) + f" | {r} |")
            lines.append("")
        for s, z in (c.get("zero_shot") or {}).items():
            e = z.get("embedding")
            sep = "n/a" if not e or e["separation"] is None else f"{e['separation']:.2f}"
            extra = "" if not e else (f"; embedding: nearest training centroid {e['nearest_centroid_distance']:.3f} vs "
                                      f"training spread {e['training_spread']:.3f} (separation {sep})")
            r = "n/a" if z["ratio"] is None else f"{z['ratio']:.2f}"
            lines.append(f"2. zero-shot `{s}`: generated {z['generated']:.3f} vs GT {z['gt']:.3f} (ratio {r}){extra}: "
                         f"{_verdict(z['holds'])}")
        if c.get("zero_shot"):
            lines.append("")
    rs = result.get("real_speech")
    if rs:
        lines += [f"Real speech: {rs['segments']} segments of {rs['segment_s']:g} s from {len(rs['files'])} file(s); "
                  "95 % intervals over segments.", "",
                  "| style | BeatAlign generated | MM (real synthetic motion) | shuffled | generated - MM | "
                  "classifier: share recognised | verdict |", "|---|---:|---:|---:|---:|---:|---|"]
        for s, r in rs["styles"].items():
            lines.append(f"| {s} | {_ci(r['generated'])} | {_ci(r['mm'])} | {_ci(r['shuffled'])} | "
                         f"{_ci(r['generated_minus_mm'])} | {r['recognised']:.3f} | {_verdict(r['holds'])} |")
        lines.append("")
    return "\n".join(lines)


def run(workdir, data_dir, *, heldout=(), heldout_seeds: int = 0, speech=(), speech_styles=SPEECH_STYLES,
        segment_s: float = 10.0, seed: int = 0, substitute: str | None = None, progress: bool = True,
        style_scale: float = 1.0) -> tuple:
    """``jaxgest zeggs evaluate --claims``: the trained model of ``workdir``, its training-script clips
    ``data_dir`` (the classifier, examples, MM), held-out folders ``heldout`` and synthetic seeds
    1..``heldout_seeds`` (criteria 1, 3, 4 and 2 for the model's ``exclude_styles``), and speech files
    ``speech`` (criterion 5); ``style_scale``: every style embedding scaled by it (1: as trained). Returns ``(result, config)``: the results and the resolved settings for the
    stamp (:func:`jaxgest.runtime.provenance.write_results`)."""
    import tempfile

    from jaxgest.motion.datasets import load_folder
    from jaxgest.zeggs.inference import load_model

    if not (heldout or heldout_seeds or speech):
        raise DataError("--claims needs held-out data (--heldout DIR... or --heldout-seeds N) or --speech WAV...")
    if substitute is not None and substitute not in SUBSTITUTES:
        raise DataError(f"--substitute {substitute!r}: choose from {', '.join(SUBSTITUTES)}")
    if not (np.isfinite(style_scale) and style_scale > 0):
        raise DataError(f"--style-scale must be finite and > 0, got {style_scale}")
    if not segment_s > 0:
        raise DataError(f"--segment-seconds must be > 0, got {segment_s}")
    for w in speech:
        if not pathlib.Path(w).is_file():
            raise DataError(f"{w}: no such speech file")
    for d in heldout:
        if not pathlib.Path(d).is_dir():
            raise DataError(f"{d}: no such held-out data folder")
    if heldout_seeds < 0:
        raise DataError(f"--heldout-seeds must be >= 0, got {heldout_seeds}")
    if not pathlib.Path(data_dir).is_dir():
        raise DataError(f"{data_dir}: no such data folder")
    model = load_model(workdir)
    train = [c for c in load_folder(data_dir) if c.audio is not None]
    if not train:
        raise DataError(f"{data_dir}: no training clip with audio")
    missing = [st for st in (speech_styles if speech else ()) if st not in {c.style for c in train}]
    if missing:
        raise DataError(f"{data_dir}: no training clip of the --speech-styles {', '.join(missing)}")
    excluded = tuple(model.cfg.train.exclude_styles)
    result = {}
    if heldout or heldout_seeds:
        with tempfile.TemporaryDirectory(prefix="jaxgest-claims-") as tmp:
            sets = heldout_datasets(heldout, heldout_seeds, tmp_dir=tmp, progress=progress)
            result["claims"] = evaluate_claims(model, train, sets, seed=seed, substitute=substitute,
                                               exclude_styles=excluded, progress=progress, style_scale=style_scale)
    if speech:
        result["real_speech"] = real_speech(model, speech, train, styles=speech_styles, segment_s=segment_s,
                                            seed=seed, progress=progress, style_scale=style_scale)
    config = {"model": model.cfg.to_dict(), "workdir": str(workdir), "checkpoint_step": int(model.step),
              "training_seed": model.meta.get("seed"), "training_data": str(data_dir),
              "heldout": [str(d) for d in heldout], "heldout_seeds": heldout_seeds,
              "speech": [str(w) for w in speech], "speech_styles": list(speech_styles), "segment_s": segment_s,
              "seed": seed, "substitute": substitute, "exclude_styles": list(excluded), "style_scale": style_scale,
              "thresholds": {"style_ratio": STYLE_RATIO, "far_above_mm": FAR_ABOVE_MM,
                             "zero_shot_ratio": ZERO_SHOT_RATIO, "realism_max": REALISM_MAX,
                             "classifier_std_floor_fraction": STD_FLOOR_FRACTION}}
    return result, config
