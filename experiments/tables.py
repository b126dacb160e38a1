"""README tables generated from stamped results files.

A README holds a generated table between ``<!-- table:NAME -->`` and ``<!-- /table -->`` (``NAME:quick`` for the
table of the ``--quick`` results). :func:`update` rewrites those blocks from the results files; :func:`check`
lists every block that differs from what its results files give (``tests/research/test_experiment_tables.py``).
Each table ends with a line naming its results files, their commit and the command that wrote them.
"""

from __future__ import annotations

import dataclasses
import pathlib
import re
from typing import Callable

import numpy as np

from experiments.driver import REPO, ROOT, DriverError, check_ran, first_of, load_config, results_path, seed_files

METHOD_LABELS = {"soft": "soft", "hard": "hard", "avatarnet": "Avatar-net", "adain": "AdaIN",
                 "autoencoder": "round trip", "content_as_is": "content as is", "style_as_is": "style as is"}


@dataclasses.dataclass(frozen=True)
class Table:
    readme: str            # README holding the table, relative to experiments/
    configs: tuple         # config files, relative to experiments/
    render: Callable       # (list of results dicts, in config order) -> markdown
    partial: bool = False  # render from the configs that have results while others have none yet


def _mean_se(x) -> tuple[float, float]:
    x = np.asarray(x, float)
    return float(x.mean()), float(x.std(ddof=1) / np.sqrt(len(x))) if len(x) > 1 else float("nan")


def _pm(x, digits=3) -> str:
    m, se = _mean_se(x)
    return f"{m:+.{digits}f} ± {se:.{digits}f}" if np.isfinite(se) else f"{m:+.{digits}f}"


def _tgst_pair_means(res: dict, pairs: str, name: str, group: str) -> dict:
    """{(content, style): value averaged over seeds} of one method or control."""
    acc: dict = {}
    for per in res["seeds"].values():
        for p in per["eval"][pairs]["per_pair"]:
            e = p["controls" if name in ("content_as_is", "style_as_is") else "errors"].get(name)
            if e is not None:
                acc.setdefault((p["content"], p["style"]), []).append(e[group])
    n = len(res["seeds"])
    return {k: float(np.mean(v)) for k, v in acc.items() if len(v) == n}


def _tgst_seed_means(res: dict, pairs: str, name: str, group: str) -> list:
    out = []
    for per in res["seeds"].values():
        ev = per["eval"][pairs]
        src = ev["controls"] if name in ("content_as_is", "style_as_is") else ev["methods"]
        if src and name in src and group in src[name]:
            out.append(src[name][group]["mean"])
    return out


def render_tables23(results: list) -> str:
    res = results[0]
    seeds = len(res["seeds"])
    first = res["_config"]["protocol"]["pairs"]
    ev0 = next(iter(res["seeds"].values()))["eval"]
    names = [m for m in ("soft", "hard", "avatarnet", "adain", "autoencoder")
             if m in ev0[first[0]]["methods"]] + ["content_as_is", "style_as_is"]
    lines = ["| | " + " | ".join(METHOD_LABELS[n] for n in names) + " |", "|---|" + "---:|" * len(names)]
    for group, unit in (("style", "m/s"), ("content", "m")):
        for pairs in first:
            cells = []
            for n in names:
                v = _tgst_seed_means(res, pairs, n, group)
                cell = f"{np.mean(v):.3f}" if v else "-"
                if v and seeds > 1 and n in ("soft", "hard"):
                    cell += f" ± {np.std(v):.3f}"
                cells.append(cell)
            lines.append(f"| {group} ({unit}), {pairs} | " + " | ".join(cells) + " |")
    cols = [(g, p) for g in ("style", "content") for p in first]
    lines += ["", "Soft swap minus X, per pair (seeds averaged per pair; mean ± standard error over pairs; "
              "pairs where soft is lower):", "",
              "| X | " + " | ".join(f"{g}, {p}" for g, p in cols) + " |", "|---|" + "---|" * len(cols)]
    for other in [n for n in names if n not in ("soft", "autoencoder")]:
        cells = []
        for group, pairs in cols:
            a, b = _tgst_pair_means(res, pairs, "soft", group), _tgst_pair_means(res, pairs, other, group)
            keys = sorted(set(a) & set(b))
            d = [a[k] - b[k] for k in keys]
            cells.append(f"{_pm(d)} ({sum(x < 0 for x in d)}/{len(d)})" if d and other != "content_as_is"
                         or d and group == "style" else "-")
        lines.append(f"| {METHOD_LABELS[other]} | " + " | ".join(cells) + " |")
    per_seed = {p: [s - h for s, h in zip(_tgst_seed_means(res, p, "soft", "style"),
                                         _tgst_seed_means(res, p, "hard", "style"))] for p in first}
    lines += ["", "Soft minus hard style error per seed (m/s): " + "; ".join(
        f"{p} " + ", ".join(f"{d:+.2f}" for d in v) for p, v in per_seed.items()) + "."]
    sw = [per["eval"][p]["swap_diagnostics"] for per in res["seeds"].values() for p in first
          if per["eval"][p].get("swap_diagnostics")]
    if sw:
        def rng(k):
            v = [s[k] for s in sw if k in s]
            lo, hi = f"{min(v):.2f}", f"{max(v):.2f}"
            return lo if lo == hi else f"{lo}-{hi}"
        lines.append(f"Soft-swap weights: largest {rng('max_weight')}, effective tokens {rng('effective_tokens')}, "
                     f"argmax within ±1 of its own index {rng('argmax_within_1')} (chance {rng('chance_within_1')}).")
    return "\n".join(lines)


def render_validity(results: list) -> str:
    from jaxgest.tgst.tables import validity_table

    return validity_table(results[0]["metric_validity"])


def render_table4(results: list) -> str:
    base, ablations = results[0], results[1:]
    lines = ["Change against the full model of the same seed (ablated minus full, soft swap; mean ± standard "
             "error over seeds; seeds with an increase):", "",
             "| loss term off | content, intra (m) | content, inter (m) | style, intra (m/s) | style, inter (m/s) |",
             "|---|---|---|---|---|"]
    for res in ablations:
        term = ",".join(res["_config"]["train"]["ablate"])
        cells = []
        for group in ("content", "style"):
            for pairs in ("intra", "inter"):
                d = [np.mean([e["methods"]["soft"][group]["mean"]]) - base["seeds"][s]["eval"][pairs]["methods"][
                    "soft"][group]["mean"] for s, per in res["seeds"].items() if s in base["seeds"]
                     for e in [per["eval"][pairs]]]
                cells.append(f"{_pm(d)} ({sum(x > 0 for x in d)}/{len(d)})" if d else "-")
        lines.append(f"| L_{term} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def render_variants(results: list) -> str:
    lines = ["| config | seeds | soft style, intra | hard style, intra | soft style, inter | hard style, inter | "
             "soft content, intra | soft - content as is, style intra |", "|---|---:|---|---|---|---|---|---|"]
    for res in results:
        cells = []
        for name, pairs, group in (("soft", "intra", "style"), ("hard", "intra", "style"), ("soft", "inter", "style"),
                                   ("hard", "inter", "style"), ("soft", "intra", "content")):
            v = _tgst_seed_means(res, pairs, name, group)
            cells.append(f"{np.mean(v):.3f} ± {np.std(v):.3f}")
        a, b = _tgst_pair_means(res, "intra", "soft", "style"), _tgst_pair_means(res, "intra", "content_as_is", "style")
        cells.append(_pm([a[k] - b[k] for k in sorted(set(a) & set(b))]))
        lines.append(f"| `{res['_config']['name']}` | {len(res['seeds'])} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def render_buckets(results: list) -> str:
    exact, bucket = results
    ex, bu = exact["seeds"]["0"]["eval"]["intra"], bucket["seeds"]["0"]["eval"]["intra"]
    evaluated = sum(bool(p["errors"]) for p in ex["per_pair"])
    lines = [f"Intra pairs, {evaluated} evaluated of {ex['num_pairs']}; bucketed minus exact shapes, per pair (mean ± "
             "standard error; the largest per-pair difference, in % of the exact error):", "",
             "| method | content, exact (m) | content diff | largest | style, exact (m/s) | style diff | largest |",
             "|---|---:|---|---:|---:|---|---:|"]
    for m in ex["methods"]:
        cells = []
        for group in ("content", "style"):
            a = {(p["content"], p["style"]): p["errors"][m][group] for p in ex["per_pair"] if m in p["errors"]}
            b = {(p["content"], p["style"]): p["errors"][m][group] for p in bu["per_pair"] if m in p["errors"]}
            keys = sorted(set(a) & set(b))
            worst = max(keys, key=lambda k: abs(b[k] - a[k]))
            cells += [f"{np.mean([a[k] for k in keys]):.3f}", _pm([b[k] - a[k] for k in keys]),
                      f"{abs(b[worst] - a[worst]):.3f} ({100 * abs(b[worst] - a[worst]) / a[worst]:.1f} %)"]
        lines.append(f"| {METHOD_LABELS.get(m, m)} | " + " | ".join(cells) + " |")
    t = [r["seeds"]["0"]["wall_s"]["eval_intra"] for r in (exact, bucket)]
    lines.append(f"\nEvaluation wall time (incl. compilation, shared cores): exact {t[0]:.0f} s, bucketed {t[1]:.0f} s.")
    sw = [r.get("swap_diagnostics") or {} for r in (ex, bu)]
    if all("padding_mass" in d for d in sw):
        lines.append(f"Soft-swap weight on padded style tokens: exact {sw[0]['padding_mass']:.3f}, bucketed "
                     f"{sw[1]['padding_mass']:.3f}; largest weight {sw[0]['max_weight']:.3f} / {sw[1]['max_weight']:.3f}.")
    return "\n".join(lines)


def render_zeggs(results: list) -> str:
    lines = ["| config | seed | style probe (pooled) | raw statistics | random init | held-out leakage z | "
             "Fréchet / floor, training scripts | held-out | held-out BeatAlign - shuffled (z) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---|"]

    def fr(rep):
        f = rep["frechet_distance"]
        return f["generated_vs_real"] / f["real_train_vs_real_test"]

    by_seed = []  # per config: {seed: (probe, leak, fr_t, fr_h, beat)}
    for res in results:
        cols = {k: [] for k in ("probe", "leak", "fr_t", "fr_h", "beat")}
        by_seed.append({})
        for seed, per in res["seeds"].items():
            pp = per.get("pooled", {}).get("probe_pooled", {}).get("style", {})
            h = per["heldout_scripts"]
            b = h["beat_alignment"]["generated_vs_control"]
            leak = h["leakage"]["contrasts"]["other_style - same_style_other_content"]["z"]
            cols["probe"].append(pp.get("trained", np.nan))
            cols["leak"].append(leak)
            cols["fr_t"].append(fr(per["training_scripts"]))
            cols["fr_h"].append(fr(h))
            cols["beat"].append(b["mean"])
            by_seed[-1][seed] = [cols[k][-1] for k in cols]
            lines.append(f"| `{res['_config']['name']}` | {seed} | {pp.get('trained', np.nan):.3f} | "
                         f"{pp.get('raw_statistics', np.nan):.3f} | {pp.get('random_init', np.nan):.3f} | {leak:.1f} | "
                         f"{fr(per['training_scripts']):.2f}x | {fr(h):.2f}x | "
                         f"{b['mean']:+.3f} ± {b['standard_error']:.3f} ({b['mean'] / b['standard_error']:.1f}) |")
        if len(res["seeds"]) > 1:
            lines.append(f"| `{res['_config']['name']}` | mean | {np.mean(cols['probe']):.3f} | | | "
                         f"{np.mean(cols['leak']):.1f} | {np.mean(cols['fr_t']):.2f}x | {np.mean(cols['fr_h']):.2f}x | "
                         f"{_pm(cols['beat'])} over seeds |")
    for res, seeds in zip(results[1:], by_seed[1:]):  # each config against the first, seed by seed
        common = [s for s in seeds if s in by_seed[0]]
        if len(common) > 1:
            d = np.array([seeds[s] for s in common]) - np.array([by_seed[0][s] for s in common])
            lines.append(f"| `{res['_config']['name']}` − `{results[0]['_config']['name']}` | paired, {len(common)} "
                         f"seeds | {_pm(d[:, 0])} | | | {_pm(d[:, 1], 2)} | {_pm(d[:, 2], 2)}x | {_pm(d[:, 3], 2)}x | "
                         f"{_pm(d[:, 4])} |")
    return "\n".join(lines)


TABLES = {
    "tgst_bandai.tables23": Table("tgst_bandai/README.md", ("tgst_bandai/configs/fit_motion.toml",), render_tables23),
    "tgst_bandai.validity": Table("tgst_bandai/README.md", ("tgst_bandai/configs/fit_motion.toml",), render_validity),
    "tgst_bandai.table4": Table("tgst_bandai/README.md", ("tgst_bandai/configs/fit_motion.toml",) + tuple(
        f"tgst_bandai/configs/ablate_{t}.toml" for t in ("identity", "cyclic", "structure", "appearance")),
        render_table4),
    "tgst_bandai.variants": Table("tgst_bandai/README.md", tuple(
        f"tgst_bandai/configs/{c}.toml" for c in ("fit", "fit_pca", "fit_smooth", "fit_motion")), render_variants),
    "tgst_evaluation.buckets": Table("tgst_evaluation/README.md", ("tgst_evaluation/configs/exact40.toml",
                                                                    "tgst_evaluation/configs/bucket40.toml"),
                                     render_buckets),
    "zeggs_synthetic.headline": Table("zeggs_synthetic/README.md", ("zeggs_synthetic/configs/small_paper_pose.toml",
                                                                    "zeggs_synthetic/configs/small.toml"), render_zeggs,
                                      partial=True),
}

CLAIMS = "claims"  # the root README's claims table (experiments/claims.py), not a TABLES entry
MARKER = re.compile(r"<!-- table:(?P<name>[\w.]+)(?P<quick>:quick)? -->\n.*?<!-- /table -->", re.S)


def load_config_results(cfg: dict) -> dict | None:
    """The results of one config, with its resolved config under ``_config``, its stamps under ``_stamps``, its
    files under ``_paths`` and the seeds still to run under ``_missing``: the config's own results file (for one
    written by ``merge``, the stamps of the runs it holds), else
    the one-seed files of ``run --seeds`` merged in the config's seed order (None when there are none)."""
    from jaxgest.runtime.provenance import read_results

    whole = results_path(cfg)
    if whole.is_file():
        if seed_files(cfg):
            raise DriverError(f"{whole}: seed files {', '.join(p.name for p in seed_files(cfg))} lie beside it; "
                              "remove them, or remove it and merge them")
        obj = read_results(whole)
        check_ran(cfg, whole, obj["stamp"]["config"])
        stamps = obj["results"].get("parts") or [obj["stamp"]]  # merged seed files: the stamps of their runs
        return {**obj["results"], "_config": obj["stamp"]["config"], "_stamps": stamps, "_paths": [whole],
                "_missing": []}
    parts = [(s, read_results(results_path(cfg, s))) for s in cfg["seeds"] if results_path(cfg, s).is_file()]
    if not parts:
        return None
    for s, obj in parts:
        check_ran(cfg, results_path(cfg, s), obj["stamp"]["config"])
    merged = {k: first_of([o["results"] for _, o in parts], k) for _, o in parts for k in o["results"]
              if k not in ("seeds", "wall_s")}
    merged["seeds"] = {str(s): obj["results"]["seeds"][str(s)] for s, obj in parts}
    merged["wall_s"] = sum(obj["results"]["wall_s"] for _, obj in parts)
    config = {**parts[0][1]["stamp"]["config"], "seeds": [s for s, _ in parts]}
    return {**merged, "_config": config, "_stamps": [obj["stamp"] for _, obj in parts],
            "_paths": [results_path(cfg, s) for s, _ in parts],
            "_missing": [s for s in cfg["seeds"] if s not in {p for p, _ in parts}]}


def load_results(name: str, quick: bool) -> list | None:
    """The results of a table's configs (:func:`load_config_results`, in config order), or None when a
    config has none (for a ``partial`` table: when none has any; the others are left out)."""
    out = [load_config_results(load_config(ROOT / c, quick)) for c in TABLES[name].configs]
    if any(r is None for r in out) and not (TABLES[name].partial and any(r is not None for r in out)):
        return None
    return [r for r in out if r is not None]


def wall_words(r: dict, named: bool = False) -> str:
    """A config's wall time in words (prefixed by its name when ``named``): the sum over its seeds, naming the
    seeds resumed from a checkpoint (whose wall time counts only the resumed part)."""
    w = r["wall_s"]
    seeds = r.get("seeds") or {}
    notes = ([f"{len(seeds)} seeds"] if len(seeds) > 1 else []) + [
        f"seed {s} resumed at step {v['train']['start_step']}" for s, v in seeds.items()
        if (v.get("train") or {}).get("start_step")]
    return ((f"`{r['_config']['name']}` " if named else "") + (f"{w / 60:.0f} min" if w >= 120 else f"{w:.0f} s")
            + (f" ({'; '.join(notes)})" if notes else ""))


def block(name: str, quick: bool) -> str | None:
    """The marked block of table ``name``: the table and a line naming its results files, commit and command."""
    results = load_results(name, quick)
    if results is None:
        return None
    readme_dir = (ROOT / TABLES[name].readme).parent
    links = [f"[`{p.name}`]({p.relative_to(readme_dir)})" for r in results for p in r["_paths"]]
    commits = sorted({(st["commit"] or "unknown")[:10] + ("+dirty" if st["dirty"] else "")
                      for r in results for st in r["_stamps"]})
    walls = ", ".join(wall_words(r, named=len(results) > 1) for r in results)
    label = "Quick smoke run (tiny step counts; not a result)" if quick else "Driver output"
    have = {r["_config"]["name"] for r in results}
    missing = "; ".join([f"`{r['_config']['name']}` seeds {', '.join(map(str, r['_missing']))} not yet run"
                         for r in results if r["_missing"]]
                        + [f"`{pathlib.Path(c).stem}` not yet run" for c in TABLES[name].configs
                           if pathlib.Path(c).stem not in have])
    words = (f"{label}; wall {walls} on 2 shared cores; commit {', '.join(commits)}; results {', '.join(links)}."
             + (f" Partial: {missing}." if missing else "")).split(" ")
    lines, line = [], ""
    for w in words:  # wrap at 110 characters: no README line over 200
        if line and len(line) + 1 + len(w) > 110:
            lines.append(line)
            line = w
        else:
            line = f"{line} {w}" if line else w
    lines.append(line)
    paths = [pathlib.Path(load_config(ROOT / c, quick)["path"]) for c in TABLES[name].configs]
    if len(paths) > 1 and len({p.parent for p in paths}) == 1:
        run_args = f"{paths[0].parent}/{{{','.join(p.stem for p in paths)}}}.toml"
    else:
        run_args = " ".join(str(p) for p in paths)
    flag = " --quick" if quick else ""
    tail = ("\n\n" + "\n".join(lines) + "\n\n"
            f"    python -m experiments run {run_args}{flag}{'   # or one seed at a time: --seeds N' if missing else ''}\n"
            f"    python -m experiments table {name}{flag}")
    return (f"<!-- table:{name}{':quick' if quick else ''} -->\n{TABLES[name].render(results)}{tail}\n"
            "<!-- /table -->")


def _readmes() -> list[pathlib.Path]:
    return sorted(ROOT.glob("*/README.md")) + [ROOT / "README.md", REPO / "README.md"]


def check() -> list[str]:
    """One line per README table that differs from its results files (or whose results are missing); the root
    README's claims table: :func:`experiments.claims.check`."""
    bad = []
    for readme in _readmes():
        if not readme.is_file():
            continue
        for m in MARKER.finditer(readme.read_text()):
            name, quick = m["name"], bool(m["quick"])
            if name not in TABLES:
                bad.append(f"{readme}: unknown table {name}")
                continue
            want = block(name, quick)
            if want is None:
                bad.append(f"{readme}: table {name}{':quick' if quick else ''} has no results files")
            elif want != m.group(0):
                bad.append(f"{readme}: table {name}{':quick' if quick else ''} differs from its results "
                           f"(regenerate: python -m experiments table {name}{' --quick' if quick else ''})")
    return bad


def update(names, quick: bool = False) -> int:
    """Rewrite the named README tables (default: all; ``claims``: the root README's claims table)."""
    names = names or [*TABLES, *([] if quick else [CLAIMS])]
    for name in names:
        if name == CLAIMS and not quick:
            from experiments import claims

            claims.update()
            continue
        if name not in TABLES:
            raise DriverError(f"unknown table {name} (python -m experiments list)")
        new = block(name, quick)
        if new is None:
            print(f"{name}: results missing (run its configs: {', '.join(TABLES[name].configs)})")
            continue
        readme = ROOT / TABLES[name].readme
        text = readme.read_text()
        tag = f"<!-- table:{name}{':quick' if quick else ''} -->"
        if tag in text:
            text = MARKER.sub(lambda m: new if m.group(0).startswith(tag + "\n") else m.group(0), text)
        else:
            text = text.rstrip("\n") + "\n\n" + new + "\n"
        readme.write_text(text)
        shown = readme.relative_to(REPO) if readme.is_relative_to(REPO) else readme
        print(f"{name}{' (quick)' if quick else ''}: written to {shown}")
    return 0
