"""The experiment driver: a config file in, a stamped results file out.

    python -m experiments run CONFIG... [--quick]     train (resumes), evaluate, write results/<config>[.quick].json,
                                                      rewrite the README tables the configs feed
    python -m experiments run CONFIG... --seeds 0 1   only those seeds, one results file each: <config>.s0.json ...
    python -m experiments merge CONFIG... [--quick]   every seed file of a config -> its whole results file
    python -m experiments table NAME [--quick]         rewrite the README tables NAME from their results files
                                                     (``claims``: the root README's claims table)
    python -m experiments table --check                 exit 1 when a README table differs from its results
    python -m experiments list                         configs and tables

A config is a TOML file in ``experiments/<experiment>/configs/`` (fields: experiments/README.md). Training and
evaluation call the package's public functions (``jaxgest.tgst.trainer.train``, ``jaxgest.tgst.evaluate``,
``jaxgest.zeggs.trainer.train``, ``jaxgest.zeggs.evaluate``) with the config's preset and dotted overrides, in one
process per ``run`` so the seeds of a config share compiled programs. Workdirs go to
``experiments/<experiment>/out/<config>[.quick]/s<seed>`` (git-ignored; a rerun resumes from their checkpoints);
the results file is written with :func:`jaxgest.runtime.provenance.write_results` (commit, version, resolved config,
command) to ``experiments/<experiment>/results/``. With ``--seeds`` each seed gets its own stamped file
(``<config>[.quick].s<seed>.json``), so a config's trainings can accumulate over several sessions; the tables
merge them (:func:`experiments.tables.load_results`) until ``merge`` folds them into the config's whole file,
which keeps each seed file's stamp under ``parts``.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import pathlib
import shlex
import sys
import time
import tomllib

ROOT = pathlib.Path(__file__).resolve().parent
REPO = ROOT.parent
TGST_METHODS = ("soft", "hard", "adain", "avatarnet", "autoencoder")
RUN_FIELDS = ("model", "preset", "overrides", "train", "data", "protocol")  # what a run of a config depends on


class DriverError(Exception):
    """A bad config, a missing data folder or results file: one line, exit status 2."""


def shared_data() -> pathlib.Path:
    """The shared data folder: ``$JAXGEST_SHARED/data``, else ``../shared/data`` beside the clone."""
    return pathlib.Path(os.environ.get("JAXGEST_SHARED", REPO.parent / "shared")) / "data"


def set_dotted(d: dict, key: str, value) -> None:
    *path, last = key.split(".")
    for p in path:
        d = d.setdefault(p, {})
    d[last] = value


def load_config(path, quick: bool = False) -> dict:
    """A config file as a dict, with its ``[quick]`` replacements applied when ``quick`` (keys are dotted
    paths into the config, e.g. ``"train.steps" = 20``), plus ``name``, ``experiment`` and ``path``."""
    path = pathlib.Path(path).resolve()
    try:
        cfg = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise DriverError(f"{path}: no such config") from None
    except tomllib.TOMLDecodeError as e:
        raise DriverError(f"{path}: not valid TOML ({e})") from None
    for key in ("model", "preset", "seeds", "table"):
        if key not in cfg:
            raise DriverError(f"{path}: missing field {key!r}")
    if cfg["model"] not in ("tgst", "zeggs"):
        raise DriverError(f"{path}: model must be 'tgst' or 'zeggs', got {cfg['model']!r}")
    quick_part = cfg.pop("quick", {})
    cfg = copy.deepcopy(cfg)
    if quick:
        for k, v in quick_part.items():
            set_dotted(cfg, k, v)
    cfg.update(name=path.stem, experiment=path.parent.parent.name, quick=quick,
               path=str(path.relative_to(REPO)) if path.is_relative_to(REPO) else str(path))
    return cfg


def results_path(cfg: dict, seed: int | None = None) -> pathlib.Path:
    """``results/<config>[.quick].json``, or with ``seed`` the one-seed file ``<config>[.quick].s<seed>.json``."""
    tail = (".quick" if cfg["quick"] else "") + (f".s{seed}" if seed is not None else "") + ".json"
    return ROOT / cfg["experiment"] / "results" / (cfg["name"] + tail)


def select_seeds(cfg: dict, seeds) -> list:
    """``seeds`` (a subset of the config's, in the config's order), or a :class:`DriverError` naming the
    config and the seeds it has."""
    unknown = [s for s in seeds if s not in cfg["seeds"]]
    if unknown:
        raise DriverError(f"{cfg['path']}: seed {unknown[0]} is not among the config's seeds {cfg['seeds']}")
    return [s for s in cfg["seeds"] if s in seeds]


def check_ran(cfg: dict, path, ran: dict) -> None:
    """A :class:`DriverError` unless the results file ``path`` (stamped config ``ran``) ran the config as it
    stands: after a config's run fields change, its results are rerun (remove the workdir
    ``out/<config>/s<seed>`` first: a rerun resumes from its checkpoints)."""
    changed = [k for k in RUN_FIELDS if ran.get(k) != cfg.get(k)]
    if changed:
        raise DriverError(f"{path}: ran another {', '.join(changed)} than {cfg['path']} has now; rerun it "
                          f"(remove its workdir under {out_dir(cfg).relative_to(ROOT)} first)")


def seed_files(cfg: dict) -> list:
    """The one-seed results files of ``cfg`` that exist, in the config's seed order."""
    return [results_path(cfg, s) for s in cfg["seeds"] if results_path(cfg, s).is_file()]


def first_of(parts: list, key: str):
    """``key`` of the first results dict in ``parts`` that has it (a part computed once per config)."""
    return next((r[key] for r in parts if key in r), None)


def out_dir(cfg: dict) -> pathlib.Path:
    return ROOT / cfg["experiment"] / "out" / (cfg["name"] + (".quick" if cfg["quick"] else ""))


# ---------------------------------------------------------------------------------------------------- TGST


def split_folder(source: pathlib.Path, dest: pathlib.Path, heldout: list, want_heldout: bool) -> pathlib.Path:
    """A folder of symlinks to the Bandai-Namco files of ``source`` whose content is (not) in ``heldout``."""
    dest.mkdir(parents=True, exist_ok=True)
    for f in sorted(source.glob("*.bvh")):
        parts = f.stem.split("_")
        content = parts[1] if len(parts) >= 4 else f.stem
        if (content in heldout) == want_heldout and not (dest / f.name).exists():
            (dest / f.name).symlink_to(f.resolve())
    if not any(dest.glob("*.bvh")):
        raise DriverError(f"{source}: no clips for this split (heldout {heldout})")
    return dest


def reuse_autoencoder(cfg: dict, source: str, seed: int, wd: pathlib.Path) -> None:
    """Copy the autoencoder checkpoint of config ``source`` (same experiment, same seed, same quick mode) into
    ``wd`` before training, as training the same autoencoder config with the same seed would give it
    bit-identically; the run then trains only the transformer."""
    import shutil

    src_cfg = {**cfg, "name": source}
    step = cfg["train"]["ae_steps"]
    src = out_dir(src_cfg) / f"s{seed}" / "checkpoints" / "autoencoder" / str(step)
    dest = wd / "checkpoints" / "autoencoder" / str(step)
    if dest.is_dir():
        return
    if not src.is_dir():
        raise DriverError(f"{src}: no autoencoder checkpoint to reuse; run configs/{source}.toml "
                          f"{'--quick ' if cfg['quick'] else ''}first")
    dest.parent.mkdir(parents=True, exist_ok=True)
    shutil.copytree(src, dest)


def compact_tgst_report(rep: dict) -> dict:
    """The numbers the tables use from a ``jaxgest.tgst.evaluate`` report: per method and control the
    averaged statistics, per pair the mean errors, the swap diagnostics, protocol and timing."""
    def means(d):
        return {m: {g: e[g]["mean"] for g in ("content", "style", "gt_content", "gt_style") if g in e}
                for m, e in (d or {}).items() if e and "skipped" not in e}

    return {
        "pairs": rep["pairs"], "num_pairs": rep["num_pairs"], "protocol": rep["protocol"],
        "methods": rep["methods"], "controls": rep.get("controls"), "swap_diagnostics": rep.get("swap_diagnostics"),
        "timing": rep.get("timing"),
        "per_pair": [{"content": pathlib.Path(p["content"]).name, "style": pathlib.Path(p["style"]).name,
                      "errors": means(p.get("errors")), "controls": means(p.get("controls"))}
                     for p in rep["per_pair"]],
    }


def run_tgst(cfg: dict, log, once: bool = True) -> dict:
    from jaxgest.tgst.evaluate import evaluate, metric_validity
    from jaxgest.tgst.trainer import train

    data, tr, pr = cfg["data"], cfg.get("train", {}), cfg.get("protocol", {})
    source = shared_data() / data["dataset"]
    if not source.is_dir():
        raise DriverError(f"{source}: no such data folder (set JAXGEST_SHARED)")
    heldout = list(data.get("heldout_contents", []))
    base = ROOT / cfg["experiment"] / "out" / "data"
    train_dir = split_folder(source, base / "train", heldout, False) if heldout else source
    eval_dir = split_folder(source, base / "eval", heldout, True) if heldout else source
    methods = tuple(pr.get("methods", TGST_METHODS))
    out = {"seeds": {}}
    for seed in cfg["seeds"]:
        wd = out_dir(cfg) / f"s{seed}"
        if tr.get("autoencoder_from"):
            reuse_autoencoder(cfg, tr["autoencoder_from"], seed, wd)
        t0 = time.perf_counter()
        summary = train(str(train_dir), str(wd), preset=cfg["preset"], ae_steps=tr.get("ae_steps"),
                        transformer_steps=tr.get("transformer_steps"), seed=seed, progress=False,
                        log_every=tr.get("log_every", 50), ckpt_every=tr.get("ckpt_every", 500),
                        ablate=tuple(tr.get("ablate", ())), overrides=dict(cfg.get("overrides", {})))
        t_train = time.perf_counter() - t0
        log(f"seed {seed}: trained in {t_train:.0f} s")
        per = {"train": {k: summary.get(k) for k in ("ae", "transformer", "devices")}, "eval": {},
               "wall_s": {"train": round(t_train, 1)}}
        for pairs in pr.get("pairs", ["intra", "inter"]):
            t0 = time.perf_counter()
            rep = evaluate(str(wd), str(eval_dir), pairs=pairs, methods=methods, progress=False,
                           protocol=pr.get("protocol", "authors"), trim_seconds=pr.get("trim"),
                           max_pairs=pr.get("max_pairs"), bucket=pr.get("bucket", 1.25),
                           style_input=pr.get("style_input", "as-is"))  # the configs' results: as is
            per["eval"][pairs] = compact_tgst_report(rep)
            per["wall_s"][f"eval_{pairs}"] = round(time.perf_counter() - t0, 1)
            log(f"seed {seed}: {pairs} pairs evaluated in {per['wall_s'][f'eval_{pairs}']:.0f} s")
        out["seeds"][str(seed)] = per
    if pr.get("validity") and once:  # Table 1: model-free, once per config (with --seeds: its first seed)
        out["metric_validity"] = metric_validity(str(eval_dir), pairs="inter", trim_seconds=pr.get("trim"),
                                                 progress=False)
    return out


# ---------------------------------------------------------------------------------------------------- ZeroEGGS


def synthetic_folder(cfg: dict, seed: int) -> pathlib.Path:
    """The built-in synthetic dataset of script seed ``seed`` (written once per experiment and length)."""
    from jaxgest.motion.synthetic import write_dataset

    seconds = cfg["data"].get("seconds", 10.0)
    dest = ROOT / cfg["experiment"] / "out" / "data" / f"synth_{seconds:g}s_seed{seed}"
    if not (dest / "manifest.csv").is_file():
        write_dataset(dest, seed=seed, seconds=seconds, progress=False)
    return dest


def compact_zeggs_report(rep: dict) -> dict:
    keep = {"probe": ("style", "content", "chance", "styles"), "leakage": ("mean_loss", "contrasts", "clips")}
    out = {k: v for k, v in rep.items() if k not in keep and k != "probe_pooled"}
    for k, fields in keep.items():
        if rep.get(k):
            out[k] = {f: rep[k][f] for f in fields if f in rep[k]}
    if "probe_pooled" in rep:
        pp = rep["probe_pooled"]
        out["probe_pooled"] = {part: {name: (v.get("accuracy") if isinstance(v, dict) else v)
                                      for name, v in pp[part].items() if name in ("trained", "random_init",
                                                                                   "raw_statistics")}
                               for part in ("style", "content")}
        out["probe_pooled"]["datasets"] = [pathlib.Path(d).name for d in pp.get("datasets") or ()]
    return out


def run_zeggs(cfg: dict, log, once: bool = True) -> dict:
    from jaxgest.zeggs.evaluate import evaluate
    from jaxgest.zeggs.trainer import train

    data, tr, pr = cfg["data"], cfg.get("train", {}), cfg.get("protocol", {})
    train_data = synthetic_folder(cfg, data.get("train_seed", 0))
    heldout = synthetic_folder(cfg, data.get("heldout_seed", 1))
    probe_dirs = [str(synthetic_folder(cfg, k)) for k in range(1, pr.get("probe_datasets", 0) + 1)]
    out = {"seeds": {}}
    for seed in cfg["seeds"]:
        wd = out_dir(cfg) / f"s{seed}"
        t0 = time.perf_counter()
        summary = train(str(train_data), str(wd), preset=cfg["preset"], steps=tr.get("steps"), seed=seed,
                        progress=False, log_every=tr.get("log_every", 50), ckpt_every=tr.get("ckpt_every"),
                        overrides=dict(cfg.get("overrides", {})))
        per = {"train": {k: summary.get(k) for k in ("steps", "start_step", "final", "steps_per_s")
                          if k in summary},
               "wall_s": {"train": round(time.perf_counter() - t0, 1)}}
        log(f"seed {seed}: trained in {per['wall_s']['train']:.0f} s")
        for name, folder, kw in (("training_scripts", train_data, {}), ("heldout_scripts", heldout, {}),
                                 ("pooled", train_data, {"probe_data": probe_dirs, "generation": False})):
            if name == "pooled" and not probe_dirs:
                continue
            t0 = time.perf_counter()
            rep = evaluate(str(wd), str(folder), seed=pr.get("eval_seed", 0), progress=False,
                           max_clips=pr.get("max_clips"), **kw)
            per[name] = compact_zeggs_report(rep)
            per["wall_s"][name] = round(time.perf_counter() - t0, 1)
            log(f"seed {seed}: {name} evaluated in {per['wall_s'][name]:.0f} s")
        out["seeds"][str(seed)] = per
    return out


# ---------------------------------------------------------------------------------------------------- commands


def run(paths, quick: bool, seeds=None) -> int:
    """Run each config; with ``seeds`` only those, each seed to its own stamped results file."""
    cfgs = [load_config(p, quick) for p in paths]  # every config checked before the first training
    jobs = [(cfg, None) for cfg in cfgs] if seeds is None else [
        (cfg, s) for cfg in cfgs for s in select_seeds(cfg, seeds)]
    for cfg, seed in jobs:
        run_one(cfg if seed is None else {**cfg, "seeds": [seed]}, quick, seed,
                once=seed is None or seed == cfg["seeds"][0])
    rewrite_tables(cfgs, quick)
    return 0


def rewrite_tables(cfgs, quick: bool) -> None:
    """Rewrite the README tables the configs feed, each once its configs' results are at hand and only where
    its README has the table's markers (a ``--quick`` smoke run adds no table to a README)."""
    from experiments import tables

    names = dict.fromkeys(n for cfg in cfgs for n in cfg["table"])
    for name in names:
        readme = tables.ROOT / tables.TABLES[name].readme if name in tables.TABLES else None
        tag = f"<!-- table:{name}{':quick' if quick else ''} -->"
        if readme and readme.is_file() and tag in readme.read_text() and tables.load_results(name, quick):
            tables.update([name], quick)


def run_one(cfg: dict, quick: bool, seed: int | None, once: bool = True) -> pathlib.Path:
    """One config (``seed`` None: all its seeds) to its stamped results file; ``once``: also the parts
    computed once per config (TGST's Table 1)."""
    from jaxgest.runtime.provenance import write_results

    t0 = time.perf_counter()
    tag = f"{cfg['name']}{' quick' if quick else ''}{f' s{seed}' if seed is not None else ''}"

    def log(msg):
        print(f"[{tag} {time.perf_counter() - t0:6.0f} s] {msg}", flush=True)

    results = (run_tgst if cfg["model"] == "tgst" else run_zeggs)(cfg, log, once)
    results["wall_s"] = round(time.perf_counter() - t0, 1)
    first = out_dir(cfg) / f"s{cfg['seeds'][0]}" / "config.json"
    if first.is_file():  # the model's resolved config (preset + overrides), as training wrote it
        cfg["resolved"] = json.loads(first.read_text()).get("config")
    results["quick"] = quick
    command = (["python", "-m", "experiments", "run", cfg["path"]] + (["--quick"] if quick else [])
               + (["--seeds", str(seed)] if seed is not None else []))
    dest = results_path(cfg, seed)
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest = write_results(dest, results, cfg, shlex.join(command),  # with the first seed's training code
                         workdir=first.parent if first.is_file() else None)
    log(f"wrote {dest.relative_to(REPO)}")
    return dest


def merge(paths, quick: bool) -> int:
    """Fold the one-seed results files of each config (every seed of the config) into its whole results file,
    stamped with this command, each seed file's stamp kept under ``results["parts"]``; the seed files are
    removed once the whole file is written."""
    from jaxgest.runtime.provenance import read_results, write_results

    cfgs = [load_config(p, quick) for p in paths]
    for cfg in cfgs:
        if results_path(cfg).is_file():
            raise DriverError(f"{results_path(cfg)}: exists; merging would replace it (remove it first to merge "
                              f"{len(seed_files(cfg))} seed file(s))")
        missing = [s for s in cfg["seeds"] if not results_path(cfg, s).is_file()]
        if missing:
            raise DriverError(f"{cfg['path']}: seeds {', '.join(map(str, missing))} have no results file yet "
                              f"(python -m experiments run {cfg['path']}{' --quick' if quick else ''} --seeds "
                              f"{' '.join(map(str, missing))})")
        for s in cfg["seeds"]:
            check_ran(cfg, results_path(cfg, s), read_results(results_path(cfg, s))["stamp"]["config"])
    for cfg in cfgs:
        files = [results_path(cfg, s) for s in cfg["seeds"]]
        parts = [read_results(f) for f in files]
        results = {k: first_of([o["results"] for o in parts], k) for o in parts for k in o["results"]
                   if k not in ("seeds", "wall_s")}
        results["seeds"] = {str(s): obj["results"]["seeds"][str(s)] for s, obj in zip(cfg["seeds"], parts)}
        results["wall_s"] = round(sum(obj["results"]["wall_s"] for obj in parts), 1)
        results["parts"] = [{"file": f.name, **{k: v for k, v in obj["stamp"].items() if k != "config"}}
                            for f, obj in zip(files, parts)]
        cfg["resolved"] = parts[0]["stamp"]["config"].get("resolved")
        command = ["python", "-m", "experiments", "merge", cfg["path"]] + (["--quick"] if quick else [])
        dest = write_results(results_path(cfg), results, cfg, shlex.join(command))
        for f in files:
            f.unlink()
        print(f"{cfg['name']}: {len(files)} seed files merged into {dest}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m experiments", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="train, evaluate and write the stamped results of each config")
    r.add_argument("configs", nargs="+")
    r.add_argument("--quick", action="store_true", help="the config's [quick] replacements (a smoke run)")
    r.add_argument("--seeds", type=int, nargs="+", metavar="SEED",
                   help="only these of the config's seeds, each to its own results file <config>.s<SEED>.json")
    m = sub.add_parser("merge", help="fold a config's one-seed results files into its whole results file")
    m.add_argument("configs", nargs="+")
    m.add_argument("--quick", action="store_true", help="the seed files of --quick runs")
    t = sub.add_parser("table", help="rewrite README tables from their results files")
    t.add_argument("names", nargs="*", help="table names (default: every table whose results exist)")
    t.add_argument("--quick", action="store_true", help="the tables of the quick results")
    t.add_argument("--check", action="store_true", help="change nothing; exit 1 if a README table differs")
    sub.add_parser("list", help="configs and tables")
    a = ap.parse_args(argv)
    from experiments import tables

    from jaxgest.runtime.errors import JaxgestError

    if a.cmd in ("run", "merge"):
        try:
            return run(a.configs, a.quick, a.seeds) if a.cmd == "run" else merge(a.configs, a.quick)
        except (DriverError, JaxgestError) as e:  # bad config or data, a full disk: one line, as the CLI does
            print(f"experiments: {e}", file=sys.stderr)
            return 2
    if a.cmd == "list":
        for c in sorted(ROOT.glob("*/configs/*.toml")):
            print(c.relative_to(REPO))
        for name in [*tables.TABLES, tables.CLAIMS]:
            print("table", name)
        return 0
    try:
        return _tables(a, tables)
    except (DriverError, JaxgestError) as e:
        print(f"experiments: {e}", file=sys.stderr)
        return 2


def _tables(a, tables) -> int:
    if a.check:
        from experiments import claims

        bad = tables.check() + claims.check()
        for line in bad:
            print(line, file=sys.stderr)
        return 1 if bad else 0
    return tables.update(a.names, quick=a.quick)
