"""README tables of this experiment from its stamped results files (results/*.json); rewrites the part of
README.md between the ``<!-- tables -->`` markers, or prints it with ``--print``.

    python experiments/tgst_bandai2/tables.py [--print]

A relation *holds* when the per-pair difference averaged over seeds is beyond 2 standard errors over pairs
and has the same sign in every seed (README, decision rules). Share of a gap: ratio of pair means, SE by
jackknife over (content clip, style) groups.
"""
import argparse
import math
import pathlib
import re
import sys
from collections import defaultdict

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
RES = HERE / "results"
CONDS = ("intra", "inter-mirror", "inter-other")
METHODS = ("soft", "hard", "adain", "avatarnet")  # the paper's four
LEVER = "coherent"  # the registered lever (README, decision rules): not in the paper
NAMES = {"soft": "soft swap", "hard": "hard swap", "adain": "AdaIN", "avatarnet": "Avatar-net",
         "coherent": "coherent swap (lever)"}


def load(name):
    from jaxgest.runtime.provenance import read_results

    p = RES / name
    return read_results(p)["results"] if p.is_file() else None


def rows_by_pair(report):
    """{(content, exemplar): (condition, rows)} of one evaluation (skipped pairs left out)."""
    return {(r["content"], r["exemplar"]): (r["condition"], r["rows"]) for r in report["pairs"] if "rows" in r}


def value(rows, row, err):
    x = rows.get(row)
    if not isinstance(x, dict) or "skipped" in x:
        return None
    return x.get(err)


def seeds_of(prefix):
    return [(s, r) for s in (0, 1, 2) if (r := load(f"eval_{prefix}_s{s}.json")) is not None]


def paired(controls, runs, cond, a, b, err, contents=None):
    """Per pair (seed-averaged) difference b - a of error ``err`` (row names: ``a`` / ``b``; a row found
    in ``controls`` (seed-independent) when not in a run). Returns (mean, se, n, per-seed means, pairs)."""
    seeds = [rows_by_pair(r) for _, r in runs]
    ctrl = rows_by_pair(controls)
    keys = [k for k, (c, _) in ctrl.items() if c == cond and (contents is None or any(x in k[0] for x in contents))]
    diffs, per_seed = [], defaultdict(list)
    for k in keys:
        ds = []
        for i, s in enumerate(seeds):
            if k not in s:
                continue
            va = value(s[k][1], a, err) if a in s[k][1] else value(ctrl[k][1], a, err)
            vb = value(s[k][1], b, err) if b in s[k][1] else value(ctrl[k][1], b, err)
            if va is None or vb is None:
                continue
            ds.append(vb - va)
            per_seed[i].append(vb - va)
        if ds:  # seeds that scored the pair (seeds 1-2 of the full runs skip the intra pairs)
            diffs.append((k, float(np.mean(ds))))
    d = np.array([x for _, x in diffs])
    if len(d) < 2:
        return None
    return d.mean(), d.std(ddof=1) / math.sqrt(len(d)), len(d), [float(np.mean(v)) for v in per_seed.values()], diffs


def holds(res, sign):
    """'holds' when sign * mean > 2 SE and every seed's mean has that sign."""
    if res is None:
        return "no data"
    m, se, _, per, _ = res
    ok = sign * m > 2 * se and all(sign * x > 0 for x in per)
    if len(per) < 3:
        return f"({'> 2 SE' if sign * m > 2 * se else '< 2 SE'}; {len(per)} seed)"
    if ok:
        return "**holds**"
    return "same sign, not significant" if sign * m > 0 else "does not hold"  # docs/design.md §11


def fmt_rel(res):
    if res is None:
        return "-"
    m, se, n, per, _ = res
    return f"{m:+.3f} +- {se:.3f} (n {n}; {'/'.join(f'{x:+.2f}' for x in per)})"


def mean_row(controls, runs, cond, row, err, contents=None):
    """Mean over pairs (per seed) then over seeds, and the std over seeds."""
    vals = []
    for _, r in (runs if runs else []):
        s = rows_by_pair(r)
        v = [value(rows, row, err) for k, (c, rows) in s.items()
             if c == cond and (contents is None or any(x in k[0] for x in contents))]
        v = [x for x in v if x is not None]
        if v:
            vals.append(np.mean(v))
    if not vals:
        s = rows_by_pair(controls)
        v = [value(rows, row, err) for k, (c, rows) in s.items()
             if c == cond and (contents is None or any(x in k[0] for x in contents))]
        v = [x for x in v if x is not None]
        return (float(np.mean(v)), None, 1) if v else (None, None, 0)
    return float(np.mean(vals)), (float(np.std(vals)) if len(vals) > 1 else None), len(vals)


def cell(m):
    v, sd, n = m
    if v is None:
        return "-"
    return f"{v:.3f}" + (f" +- {sd:.3f}" if sd is not None else "") + (f" ({n})" if n and n != 3 else "")


def share(controls, runs, cond, control_row, err, contents=None, method="soft|mirror"):
    """(control - method) / (control - floor) on ``err`` (default the soft swap, mirror input); jackknife SE
    over groups."""
    seeds = [rows_by_pair(r) for _, r in runs]
    ctrl = rows_by_pair(controls)
    items = []
    for k, (c, rows) in ctrl.items():
        if c != cond or (contents is not None and not any(x in k[0] for x in contents)):
            continue
        soft = [value(s[k][1], method, err) for s in seeds if k in s]
        soft = [x for x in soft if x is not None]
        ctl, floor = value(rows, control_row, err), value(rows, "gt_take", err)
        if soft and ctl is not None and floor is not None:
            style = k[1].split("_")[-2]
            items.append((f"{k[0]}|{style}", ctl - np.mean(soft), ctl - floor))
    if len(items) < 3:
        return None
    groups = sorted({g for g, _, _ in items})
    num = np.array([a for _, a, _ in items]); den = np.array([b for _, _, b in items])
    full = num.mean() / den.mean()
    jk = []
    for g in groups:
        keep = np.array([x != g for x, _, _ in items])
        jk.append(num[keep].mean() / den[keep].mean())
    jk = np.array(jk)
    se = math.sqrt((len(groups) - 1) / len(groups) * ((jk - jk.mean()) ** 2).sum())
    return full, se, len(items)


def table1(t1):
    out = ["| condition (style sample's gesture) | triples | content err: content sample / style sample | "
           "content metric holds on | style err: content sample / style sample | style metric holds on |",
           "|---|---:|---:|---:|---:|---:|"]
    notes = []
    sp = defaultdict(list)  # log arm speed per content x style cell (all takes)
    for r in t1["arm_speeds"]:
        sp[r["cell"]].append(math.log(r["speed"]))
    cells = {k: np.mean(v) for k, v in sp.items()}
    for cond in ("inter-mirror", "inter-other"):
        x = [q for q in t1["triples"] if q["condition"] == cond]
        c, s = np.array([q["content"] for q in x]), np.array([q["style"] for q in x])
        dc, ds = c[:, 1] - c[:, 0], s[:, 0] - s[:, 1]
        refs = defaultdict(lambda: [[], []])
        for q, a, b in zip(x, dc, ds):
            refs[q["reference"]][0].append(a), refs[q["reference"]][1].append(b)
        fail_c = np.mean([np.mean(v[0]) <= 0 for v in refs.values()])
        fail_s = np.mean([np.mean(v[1]) <= 0 for v in refs.values()])
        notes.append(f"{cond}: the relation fails (mean over the reference's triples) on {fail_c:.0%} of the "
                     f"{len(refs)} references for the content metric, {fail_s:.0%} for the style metric.")
        out.append(f"| {cond} | {len(x)} | {c[:, 0].mean():.3f} / {c[:, 1].mean():.3f} m "
                   f"(diff {dc.mean():+.3f} +- {dc.std(ddof=1) / math.sqrt(len(dc)):.3f}) | "
                   f"{(dc > 0).sum()}/{len(x)} ({(dc > 0).mean():.0%}) | {s[:, 0].mean():.3f} / {s[:, 1].mean():.3f} m/s "
                   f"(diff {ds.mean():+.3f} +- {ds.std(ddof=1) / math.sqrt(len(ds)):.3f}) | "
                   f"{(ds > 0).sum()}/{len(x)} ({(ds > 0).mean():.0%}) |")
    within = np.mean([np.var(v, ddof=1) for v in sp.values()])
    gest = lambda c: c.split("/")[0].replace("-left", "").replace("-right", "")
    styles = sorted({k.split("/")[1] for k in cells})
    gestures = sorted({gest(k) for k in cells})
    by_style = np.var([np.mean([v for k, v in cells.items() if k.endswith("/" + s)]) for s in styles], ddof=1)
    by_gesture = np.var([np.mean([v for k, v in cells.items() if gest(k) == g]) for g in gestures], ddof=1)
    out += [""] + notes
    cell_of = lambda n: "/".join(n[:-4].split("_")[1:3])
    for cond in ("inter-mirror", "inter-other"):  # cause: the style metric against the styles' speed gap
        x = [q for q in t1["triples"] if q["condition"] == cond]
        gap = np.array([abs(cells[cell_of(q["reference"])] - cells[cell_of(q["content_sample"])]) for q in x])
        ok = np.array([q["style"][1] < q["style"][0] for q in x])
        bins = [(0, .3), (.3, .7), (.7, 99)]
        out.append(f"{cond}, style metric holds by |log arm-speed ratio| of the two styles (cell means): " + "; ".join(
            f"{lo:g}-{hi if hi < 99 else 'max'}: {ok[(gap >= lo) & (gap < hi)].mean():.0%} of "
            f"{((gap >= lo) & (gap < hi)).sum()}" for lo, hi in bins) + ".")
    out.append("")
    out.append(f"Log mean arm speed (all 224 clips): variance between styles {by_style:.3f}, between the two "
               f"gestures {by_gesture:.3f}, between takes of one cell {within:.3f}.")
    return "\n".join(out), within


def main_tables(controls, runs):
    out = []
    for cond in CONDS:
        out.append(f"\n**{cond}** ({sum(1 for c, _ in rows_by_pair(controls).values() if c == cond)} pairs; "
                   "mean over pairs, then over seeds +- std over seeds; content m, style m/s)\n")
        out.append("| row | content (vs content clip) | style (vs exemplar + mirror) | gt_content | gt_style |")
        out.append("|---|---:|---:|---:|---:|")
        rows = [(f"{NAMES[m]}, exemplar + mirror", f"{m}|mirror", runs) for m in (*METHODS, LEVER)]
        rows += [(f"{NAMES[m]}, exemplar as is (seed 0)", f"{m}|as_is", runs[:1]) for m in (*METHODS, LEVER)]
        rows += [("AE round trip", "autoencoder", runs), ("PCA-16 round trip", "pca16", runs),
                 ("hands oracle, as is (seed 0, every 4th pair)", "oracle_hands|as_is", runs[:1]),
                 ("hands oracle, + mirror (seed 0, every 4th pair)", "oracle_hands|mirror", runs[:1]),
                 ("hands collage at a constant rate, as is (seed 0, every 4th pair)", "oracle_rate|as_is", runs[:1]),
                 ("hands collage at a constant rate, + mirror (seed 0, every 4th pair)", "oracle_rate|mirror",
                  runs[:1]),
                 ("content as is", "content_as_is", []), ("style as is", "style_as_is", []),
                 ("a ground-truth take (gt columns: floor)", "gt_take", []),
                 ("collage bound, exemplar frames", "collage|as_is", []),
                 ("collage bound, + mirrored frames", "collage|mirror", [])]
        for label, row, rr in rows:
            out.append(f"| {label} | " + " | ".join(cell(mean_row(controls, rr, cond, row, e))
                                                     for e in ("content", "style", "gt_content", "gt_style")) + " |")
    return "\n".join(out)


def relations(controls, runs, contents=None, method="soft|mirror"):
    name = NAMES[method.split("|")[0]].split(" (")[0]
    out = [f"| condition | {name} - style as is, gt_content (< 0; seeds) | {name} - content as is, gt_style (< 0) | "
           "gap share, style | gap share, content |", "|---|---|---|---|---|"]
    for cond in CONDS:
        r1 = paired(controls, runs, cond, "style_as_is", method, "gt_content", contents)
        r2 = paired(controls, runs, cond, "content_as_is", method, "gt_style", contents)
        s1 = share(controls, runs, cond, "content_as_is", "gt_style", contents, method)
        # intra: "style as is" is itself a ground-truth take (the floor), so the content gap is empty
        s2 = share(controls, runs, cond, "style_as_is", "gt_content", contents, method) if cond != "intra" else None
        f = lambda s: "-" if s is None else f"{s[0]:.0%} +- {s[1]:.0%}"
        out.append(f"| {cond} | {fmt_rel(r1)} {holds(r1, -1)} | {fmt_rel(r2)} {holds(r2, -1)} | {f(s1)} | {f(s2)} |")
    return "\n".join(out)


def steps(runs, variant="mirror"):
    """How the soft swap's argmax (the hard swap's choice) moves between consecutive content tokens: the
    fractions of +1 / 0 / back / > 2 steps through the style clip, mean over pairs and seeds, per condition."""
    out = []
    for cond in CONDS:
        per = defaultdict(list)
        for _, r in runs:
            for p in r["pairs"]:
                d = p.get(f"swap|{variant}")
                if p["condition"] == cond and d and d.get("step_one") is not None:
                    for k in ("one", "zero", "back", "far"):
                        per[k].append(d[f"step_{k}"])
        if per:
            out.append(f"{cond} {np.nanmean(per['one']):.0%} / {np.nanmean(per['zero']):.0%} / "
                       f"{np.nanmean(per['back']):.0%} / {np.nanmean(per['far']):.0%}")
    if not out:
        return ""
    return ("Swap argmax steps between content tokens (+1 = the style's timing / 0 / back / > 2): "
            + "; ".join(out) + ".")


def ordering(controls, runs):
    out = ["| condition | order on gt_style (mirror input) | soft - next best, gt_style | "
           "order on style vs exemplar |", "|---|---|---|---|"]
    for cond in CONDS:
        g = {m: mean_row(controls, runs, cond, f"{m}|mirror", "gt_style")[0] for m in METHODS}
        e = {m: mean_row(controls, runs, cond, f"{m}|mirror", "style")[0] for m in METHODS}
        if any(v is None for v in g.values()):
            continue
        order = sorted(g, key=g.get)
        best = next(m for m in order if m != "soft")
        r = paired(controls, runs, cond, f"{best}|mirror", "soft|mirror", "gt_style")
        short = {"soft": "soft", "hard": "hard", "adain": "AdaIN", "avatarnet": "Avatar"}
        out.append(f"| {cond} | " + " < ".join(f"{short.get(m, m)} {g[m]:.2f}" for m in order) +
                   f" | {fmt_rel(r)} {holds(r, -1)} | "
                   + " < ".join(f"{short.get(m, m)} {e[m]:.2f}" for m in sorted(e, key=e.get)) + " |")
    return "\n".join(out)


def round_trip(runs, spread):
    out = ["| run | clips | mean of per-clip ratios | geometric mean | within 5 % (registered / geometric) |",
           "|---|---:|---:|---:|---|"]
    for name, r in runs:
        x = np.array([q["output"] / q["input"] for q in r["round_trip"]])
        m, gm = x.mean(), math.exp(np.log(x).mean())
        out.append(f"| {name} | {len(x)} | {m:.3f} | {gm:.3f} | {'yes' if abs(m - 1) <= .05 else 'no'} / "
                   f"{'yes' if abs(gm - 1) <= .05 else 'no'} |")
    out.append(f"\nTake-to-take spread of arm speed within one content x style cell: std of log speed "
               f"{math.sqrt(spread):.3f} (a factor of {math.exp(math.sqrt(spread)):.2f}).")
    return "\n".join(out)


def compact_table(controls, runs):
    """gt_content / gt_style of the headline rows in the three conditions (the full rows: TABLES.md)."""
    rows = [(f"{NAMES[m]}, exemplar + mirror", f"{m}|mirror", runs) for m in (*METHODS, LEVER)]
    rows += [("soft swap, exemplar as is (seed 0)", "soft|as_is", runs[:1]), ("AE round trip", "autoencoder", runs),
             ("hands collage, nearest token, + mirror (seed 0, 1/4 of pairs)", "oracle_hands|mirror", runs[:1]),
             ("hands collage, constant rate, + mirror (seed 0, 1/4 of pairs)", "oracle_rate|mirror", runs[:1]),
             ("content as is", "content_as_is", []), ("style as is", "style_as_is", []),
             ("a ground-truth take (floor)", "gt_take", []), ("collage bound, + mirrored frames", "collage|mirror", [])]
    out = ["| row (gt_content m / gt_style m/s) | " + " | ".join(CONDS) + " |", "|---" + "|---:" * len(CONDS) + "|"]
    for label, row, rr in rows:
        out.append(f"| {label} | " + " | ".join(
            f"{cell(mean_row(controls, rr, c, row, 'gt_content')).split(' ')[0]} / "
            f"{cell(mean_row(controls, rr, c, row, 'gt_style')).split(' ')[0]}" for c in CONDS) + " |")
    return "\n".join(out)


def extra_tables(full):
    """The zero-shot pairs in the full runs and under the lever, and the Bandai-Namco-1 addition (seed 0)."""
    controls, parts = full[0][1], []
    zero = [(f"zeroshot_s{s}", r) for s, r in seeds_of("zeroshot")]
    held = ["wave-right-hand"]
    parts += ["", "## Zero-shot pairs (content wave-right-hand), full runs", "", relations(controls, full, held)]
    if zero and any(f"{LEVER}|mirror" in (p.get("rows") or {}) for _, r in zero for p in r["pairs"]):
        parts += ["", "## Zero-shot runs, the lever", "", relations(controls, zero, held, f"{LEVER}|mirror")]
    extra = load("eval_bn1plus_s0.json")
    if extra:
        parts += ["", "## Adding Bandai-Namco-1 to the training data (seed 0 only)", "",
                  "Trained on Bandai-Namco-2 takes 001-004 + all of Bandai-Namco-1:", "",
                  relations(controls, [("bn1plus_s0", extra)]), "", "Same pairs, Bandai-Namco-2 only (seed 0):",
                  "", relations(controls, [("full_s0", controls)])]
    return "\n".join(parts)


def build():
    t1 = load("table1.json")
    parts = []
    spread = None
    if t1:
        text, spread = table1(t1)
        parts += ["### Table 1, cross form (data only, test takes)", "", text]
    full = [(f"full_s{s}", r) for s, r in seeds_of("full")]
    zero = [(f"zeroshot_s{s}", r) for s, r in seeds_of("zeroshot")]
    controls = dict(full).get("full_s0")
    if controls:
        runs = [(n, r) for n, r in full]
        parts += ["", f"### Tables 2-3 on the test takes, against the ground truth ({len(runs)} seed(s); every row and "
                  "column with its spread over seeds: [TABLES.md](TABLES.md))", "", compact_table(controls, runs)]
        parts += ["", "### Relations (exemplar + mirror input; soft swap)", "", relations(controls, runs)]
        parts += ["", "### The four methods on style vs ground truth", "", ordering(controls, runs)]
        if any(f"{LEVER}|mirror" in (p.get("rows") or {}) for _, r in runs for p in r["pairs"]):
            parts += ["", "### The lever: the time-coherent swap (registered; not in the paper)", "",
                      relations(controls, runs, method=f"{LEVER}|mirror"), "", steps(runs)]
        if zero:
            parts += ["", f"### Zero-shot: content wave-right-hand held out of training ({len(zero)} seed(s); the "
                      "same pairs in the full runs and the lever: [TABLES.md](TABLES.md))", "",
                      relations(controls, zero, ["wave-right-hand"])]
        if spread is not None:
            parts += ["", "### Round trip: arm speed of the AE output over the input's (test clips)", "",
                      round_trip(full + zero, spread)]
    return "\n".join(parts)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--print", action="store_true")
    a = ap.parse_args()
    text = build()
    full = [(f"full_s{s}", r) for s, r in seeds_of("full")]
    if full:
        (HERE / "TABLES.md").write_text("# TGST on Bandai-Namco-2: Tables 2-3 in full (generated by tables.py)\n"
                                        + main_tables(full[0][1], full) + "\n" + extra_tables(full) + "\n")
    if a.print:
        print(text)
        return 0
    readme = HERE / "README.md"
    s = readme.read_text()
    block = f"<!-- tables -->\n{text}\n<!-- /tables -->"
    if "<!-- tables -->" in s:
        s = re.sub(r"<!-- tables -->.*<!-- /tables -->", lambda _: block, s, flags=re.S)
    else:
        s = s.rstrip() + "\n\n" + block + "\n"
    readme.write_text(s)
    return 0


if __name__ == "__main__":
    sys.exit(main())
