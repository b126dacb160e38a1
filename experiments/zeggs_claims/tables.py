"""The tables of this experiment's README and TABLES.md, generated from its stamped results files
(results/claims_RUN.json, written by run.sh with `jaxgest zeggs evaluate --claims`). Rewrites the README between its
table markers and TABLES.md.

Usage (from anywhere): python experiments/zeggs_claims/tables.py [--print]
"""

from __future__ import annotations

import argparse
import math
import pathlib
import re

from jaxgest.runtime.io import write_text_atomic
from jaxgest.runtime.provenance import read_results

HERE = pathlib.Path(__file__).resolve().parent
RESULTS = HERE / "results"
MAIN = [f"small_s{k}" for k in range(5)]
ZERO_SHOT = [f"zs_{s}_s{k}" for s in ("sad", "tense") for k in range(2)]
PILOTS = ["pilot", "pilot_zs_sad"]
LEVER = [f"{r}_scale2" for r in MAIN + ZERO_SHOT]


def judge_corrected(doc) -> bool:
    """Evaluated with the style classifier's std floor (commit ed6cc57)? Earlier results let rounding-noise
    channels (planted feet) decide the classifier and are not counted."""
    return "classifier_std_floor_fraction" in (doc["stamp"]["config"].get("thresholds") or {})


def _read(run):
    p = RESULTS / f"claims_{run}.json"
    return read_results(p) if p.is_file() else None


def load(run):
    """The results of ``run`` when they were evaluated with the corrected judge (else None)."""
    doc = _read(run)
    return doc if doc and judge_corrected(doc) else None


def stale_runs() -> list:
    """Runs whose results file predates the judge's correction (re-evaluate them: run.sh RUN)."""
    return [r for r in MAIN + ZERO_SHOT + LEVER if (d := _read(r)) and not judge_corrected(d)]


def ci(s) -> str:
    """Mean and the interval's half-width (the interval is symmetric: mean +- 1.96 SE)."""
    return f"{s['mean']:.3f} ± {(s['high'] - s['low']) / 2:.3f}"


def yes(ok) -> str:
    return "holds" if ok else "no"


def _get(results: dict, key: str):
    """``results`` at the dotted path ``key`` (None where a part is missing)."""
    for part in key.split("."):
        results = results.get(part) if isinstance(results, dict) else None
    return results


def _section(runs, key, title) -> tuple:
    """The runs whose results file has a non-empty dotted ``key``, with their documents, and the heading lines."""
    docs = [(r, d) for r, d in ((r, load(r)) for r in runs) if d and _get(d["results"], key)]
    return docs, [f"### {title}", ""]


NEED, OF = 4, 5  # a claim holds on synthetic data when it holds in >= 4 of the 5 `small` seeds


def verdict(held: int, ran: int, need: int = NEED, of: int = OF, effect: float | None = None) -> str:
    """The pre-registered rule over runs, decided as soon as the remaining runs cannot change it. A failed rule
    reads **same sign, not significant** when the mean ``effect`` over runs (positive: the claimed side of the
    rule's threshold) has the claimed sign, **does not hold** otherwise: the project's one verdict rule
    (docs/design.md §11, experiments/claims.py, which computes the same effects for the root table)."""
    if held >= need:
        return f"**holds** ({held} / {ran})"
    failed = "**same sign, not significant**" if effect is not None and effect > 0 else "**does not hold**"
    if ran >= of:
        return f"{failed} ({held} / {ran})"
    if ran - held > of - need:
        return f"{failed} ({held} / {ran}: >= {need} of {of} no longer possible)"
    return f"open ({held} / {ran} so far)"


def _threshold(docs, name: str) -> float:
    """A registered threshold of the runs ``docs`` ((run, doc) pairs; their stamps' config): the same in all."""
    values = {float(d["stamp"]["config"]["thresholds"][name]) for _, d in docs}
    if len(values) != 1:
        raise ValueError(f"zeggs_claims: runs judged with different {name}: {sorted(values)}")
    return values.pop()


def _mean(xs):
    return sum(xs) / len(xs) if xs else float("nan")


def verdict_table(title) -> list:
    """One row per paper claim: the measure, model / GT / MM (means over runs), runs where it holds, verdict."""
    lines = [f"### {title}", "", "| paper's claim (its finding) | measure here | model | GT | MM | verdict |",
             "|---|---|---|---|---|---|"]
    docs = _section(MAIN, "claims", "")[0]
    if docs:
        c = [d["results"]["claims"] for _, d in docs]
        sp, re_, ap = ([x[k] for x in c] for k in ("style_portrayal", "realism", "appropriateness"))
        lines += [
            f"| style portrayal (above MM) | classifier accuracy, generated >= 0.9 GT | "
            f"{_mean([x['generated']['mean'] for x in sp]):.3f} | {_mean([x['gt']['mean'] for x in sp]):.3f} | "
            f"{_mean([x['mm']['mean'] for x in sp]):.3f} | "
            f"{verdict(sum(x['holds'] for x in sp), len(sp), effect=_mean([x['ratio_to_gt'] - _threshold(docs, 'style_ratio') for x in sp]))} |",
            f"| naturalness (tied with MM) | Fréchet / real other-script, geometric mean <= 1 | "
            f"{_mean([x['geometric_mean_ratio'] for x in re_]):.2f} | 0 | 1 | "
            f"{verdict(sum(x['holds'] for x in re_), len(re_), effect=-_mean([math.log(x['geometric_mean_ratio']) for x in re_]))} |",
            f"| appropriateness (above MM) | BeatAlign vs the speech, generated > MM | "
            f"{_mean([x['generated']['mean'] for x in ap]):.3f} | {_mean([x['gt']['mean'] for x in ap]):.3f} | "
            f"{_mean([x['mm']['mean'] for x in ap]):.3f} | "
            f"{verdict(sum(x['holds'] for x in ap), len(ap), effect=_mean([x['generated_minus_mm']['mean'] for x in ap]))} |"]
    zs, zs_docs = {}, _section(ZERO_SHOT, "claims.zero_shot", "")[0]
    for _, d in zs_docs:
        for st, z in d["results"]["claims"]["zero_shot"].items():
            zs.setdefault(st, []).append(z)
    for st, zz in sorted(zs.items()):
        lines.append(f"| zero-shot style `{st}` (reproduced from one example) | left-out style accuracy >= 0.5 GT, "
                     f"embeddings apart | {_mean([z['generated'] for z in zz]):.3f} | {_mean([z['gt'] for z in zz]):.3f} | "
                     f"{_mean([z['mm'] for z in zz]):.3f} | "
                     f"{verdict(sum(z['holds'] for z in zz), len(zz), 2, 2, effect=_mean([z['ratio'] - _threshold(zs_docs, 'zero_shot_ratio') for z in zz]))} |")
    sd = _section(MAIN, "real_speech", "")[0]
    styles = sorted({st for _, d in sd for st in d["results"]["real_speech"]["styles"]})
    for st in styles:
        xs = [d["results"]["real_speech"]["styles"][st] for _, d in sd if st in d["results"]["real_speech"]["styles"]]
        lines.append(f"| appropriateness on real speech, `{st}` | BeatAlign generated > MM | "
                     f"{_mean([x['generated']['mean'] for x in xs]):.3f} | | {_mean([x['mm']['mean'] for x in xs]):.3f} | "
                     f"{verdict(sum(x['holds'] for x in xs), len(xs), effect=_mean([x['generated']['mean'] - x['mm']['mean'] for x in xs]))} |")
    if len(lines) == 4:
        lines.append("| not yet run | | | | | |")
    return lines + ["", "Rule (pre-registered): holds in >= 4 of 5 `small` seeds; zero-shot: in both seeds of the style. "
                   "Otherwise same sign, not significant when the mean over runs is on the claimed side, else does "
                   "not hold.", ""]


def claims_table(runs, title, per_style: bool = True) -> list:
    docs, lines = _section(runs, "claims", title)
    if not docs:
        return lines + ["not yet run", ""]
    lines += ["| run (step) | 1. style: generated | GT | MM | ratio | 3. realism: Fréchet ratio (geo. mean) | "
              "4. BeatAlign generated - MM | generated - shuffled | GT - MM |", "|---|---|---|---|---|---|---|---|---|"]
    n = {"style_portrayal": 0, "realism": 0, "appropriateness": 0}
    for r, d in docs:
        c, step = d["results"]["claims"], d["stamp"]["config"].get("checkpoint_step")
        sp, re_, ap = c["style_portrayal"], c["realism"], c["appropriateness"]
        for k in n:
            n[k] += bool(c[k]["holds"])
        lines.append(f"| {r} ({step}) | {ci(sp['generated'])} | {ci(sp['gt'])} | {ci(sp['mm'])} | "
                     f"{sp['ratio_to_gt']:.2f}: {yes(sp['holds'])} | {re_['geometric_mean_ratio']:.2f} "
                     f"[{re_['ratio_low']:.2f}, {re_['ratio_high']:.2f}]: {yes(re_['holds'])} | "
                     f"{ci(ap['generated_minus_mm'])}: {yes(ap['holds'])} | {ci(ap['generated_minus_shuffled'])} | "
                     f"{ci(ap['gt_minus_mm'])} |")
    lines += ["", f"Holds in: style portrayal {n['style_portrayal']} / {len(docs)}, realism {n['realism']} / "
              f"{len(docs)}, appropriateness {n['appropriateness']} / {len(docs)} runs (a claim holds when >= 4 of 5).", ""]
    if not per_style:
        return lines
    styles = sorted(docs[0][1]["results"]["claims"]["style_portrayal"]["per_style"])
    lines += ["| style: accuracy generated / GT / MM (mean over runs) |" + "|".join(f" {s} " for s in styles) + "|",
              "|---|" + "---|" * len(styles)]
    cells = []
    for s in styles:
        ps = [d["results"]["claims"]["style_portrayal"]["per_style"][s] for _, d in docs]
        cells.append(" / ".join(f"{sum(p[k] for p in ps) / len(ps):.2f}" for k in ("generated", "gt", "mm")))
    return lines + ["| |" + "|".join(f" {c} " for c in cells) + "|", ""]


def speed_table(runs, title) -> list:
    """The measured cause of criterion 1 (diagnostic): hand speed generated / GT, per style, and handedness."""
    docs, lines = _section(runs, "claims.hand_speeds", title)
    if not docs:
        return lines + ["not yet measured (results files before the diagnostic)", ""]
    styles = sorted(docs[0][1]["results"]["claims"]["hand_speeds"]["per_style"])
    lines += ["| run | hand speed generated / GT (all) |" + "|".join(f" {s} " for s in styles)
              + "| left hand's share: generated / GT |", "|---|---|" + "---|" * len(styles) + "---|"]
    for r, d in docs:
        h = d["results"]["claims"]["hand_speeds"]
        cells = [f"{h['per_style'][s]['ratio']:.2f}" if h["per_style"][s]["ratio"] is not None else "" for s in styles]
        lines.append(f"| {r} | {ci(h['ratio'])} |" + "|".join(f" {c} " for c in cells)
                     + f"| {h['left_share']['generated']:.2f} / {h['left_share']['gt']:.2f} |")
    return lines + [""]


def zero_shot_table(runs, title) -> list:
    docs, lines = _section(runs, "claims.zero_shot", title)
    if not docs:
        return lines + ["not yet run", ""]
    lines += ["| run | left-out style | generated | GT | MM | ratio (>= 0.5) | embedding: nearest training centroid / "
              "training spread (separation > 1) | verdict |", "|---|---|---|---|---|---|---|---|"]
    for r, d in docs:
        for s, z in d["results"]["claims"]["zero_shot"].items():
            e = z.get("embedding") or {}
            emb = (f"{e['nearest_centroid_distance']:.3f} / {e['training_spread']:.3f} ({e['separation'] or float('nan'):.2f}; "
                   f"nearest: {max(e['nearest_style_counts'], key=e['nearest_style_counts'].get)})") if e else ""
            ratio = "n/a" if z["ratio"] is None else f"{z['ratio']:.2f}"
            lines.append(f"| {r} | {s} | {z['generated']:.3f} | {z['gt']:.3f} | {z['mm']:.3f} | {ratio} | {emb} | "
                         f"{yes(z['holds'])} |")
    return lines + [""]


def speech_table(runs, title) -> list:
    """Per run, per style: BeatAlign generated - MM and - shuffled (intervals over segments), the verdict, and the
    classifier's share of windows recognised as the style (its GT accuracy on held-out clips in brackets)."""
    docs, lines = _section(runs, "real_speech", title)
    if not docs:
        return lines + ["not yet run", ""]
    styles = sorted({s for _, d in docs for s in d["results"]["real_speech"]["styles"]})
    lines += ["| run (segments) |" + "|".join(f" `{s}`: BeatAlign generated - MM; - shuffled; recognised (GT) " for s in styles)
              + "|", "|---|" + "---|" * len(styles)]
    for r, d in docs:
        rs = d["results"]["real_speech"]
        per = d["results"].get("claims", {}).get("style_portrayal", {}).get("per_style", {})
        cells = []
        for s in styles:
            x = rs["styles"].get(s)
            gt = f" ({per[s]['gt']:.2f})" if s in per else ""
            cells.append("" if x is None else f"{ci(x['generated_minus_mm'])}: {yes(x['holds'])}; "
                         f"{ci(x['generated_minus_shuffled'])}; {x['recognised']:.2f}{gt}")
        lines.append(f"| {r} ({rs['segments']}) |" + "|".join(f" {c} " for c in cells) + "|")
    return lines + [""]


def tables() -> str:
    """The README's tables: the verdicts, claims 1, 3, 4 per run and zero-shot."""
    stale = stale_runs()
    note = ([f"Not counted, evaluated before the judge's correction (re-evaluate): {', '.join(stale)}.", ""]
            if stale else [])
    return "\n".join(
        note + verdict_table("Verdicts: which of the paper's claims hold on synthetic data")
        + claims_table(MAIN, "Table 1. Claims 1, 3, 4: `small`, 8,000 steps, 5 seeds (`run.sh`)")
        + zero_shot_table(ZERO_SHOT, "Table 2. Claim 2, zero-shot: 2 seeds per left-out style (`run.sh`)")
        + ["Tables 3-5 (real speech, the cause of claim 1, the lever): [TABLES.md](TABLES.md)."])


def detail_tables() -> str:
    """TABLES.md: real speech, the measured cause of claim 1, the lever."""
    return "\n".join(
        ["# ZeroEGGS claims: detail tables", "",
         "Generated by `python experiments/zeggs_claims/tables.py` from `results/claims_RUN.json`; read with the README.", ""]
        + speech_table(MAIN, "Table 3. Claim 5, real speech (ZEGGS + BEAT2 WAVs), 2 styles (`run.sh`)")
        + speed_table(MAIN + ZERO_SHOT + LEVER, "Table 4. The cause measured for claim 1: hand speed and handedness "
                      "(diagnostic, not a gate; `_scale2`: the lever of Table 5)")
        + claims_table(LEVER, "Table 5. Lever against damping: style embeddings x 2 (`--style-scale 2`), same models "
                       "(hand speed: Table 4)", per_style=False)).rstrip() + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--print", action="store_true", help="print the tables instead of rewriting the README")
    args = ap.parse_args()
    text = tables()
    if args.print:
        print(text + "\n\n" + detail_tables())
        return
    write_text_atomic(HERE / "TABLES.md", detail_tables())
    readme = HERE / "README.md"
    old = readme.read_text()
    new = re.sub(r"(<!-- tables:start -->\n).*(<!-- tables:end -->)", lambda m: m.group(1) + text + "\n" + m.group(2),
                 old, flags=re.DOTALL)
    write_text_atomic(readme, new)
    print(f"tables.py: rewrote the tables of {readme} and {HERE / 'TABLES.md'}")


if __name__ == "__main__":
    main()
