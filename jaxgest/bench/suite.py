"""``jaxgest bench [--quick] [--json OUT] [--plot OUT.png] [--cases PATTERN] [--repeats N]``.

Runs the registered cases (``jaxgest/bench/cases/``), prints progress, then a markdown table of every record
and a table of eager/jit and numpy/jit ratios. ``python -m jaxgest.bench`` (and the clone's ``python -m benchmarks``) is the same.
Exit status 0; 1 when an implementation failed its equality check (that case is reported, not timed);
2 on a usage error (no case matches, unwritable output).
"""

from __future__ import annotations

import argparse
import fnmatch
import importlib.util
import json
import os
import sys
import time

from jaxgest.bench import harness, machine, report
from jaxgest.bench.cases import all_cases
from jaxgest.bench.options import add_arguments
from jaxgest.bench.records import validate_document
from jaxgest.runtime import provenance
from jaxgest.runtime.errors import JaxgestError
from jaxgest.runtime.io import check_output_path, write_text_atomic

QUICK_REPEATS, FULL_REPEATS = 3, 7
QUICK_BUDGET_S, FULL_BUDGET_S = 4.0, 20.0  # timed repeats per implementation (at least 2 repeats)


def build_parser() -> argparse.ArgumentParser:
    return add_arguments(argparse.ArgumentParser(prog="jaxgest bench",
                                                 description="jaxgest per-pose CPU cost benchmarks"))


def select(cases: list, pattern: str | None) -> list:
    """Cases whose name matches one comma-separated alternative (glob if it has ``*?[``, else substring)."""
    if not pattern:
        return list(cases)
    pats = [p.strip() for p in pattern.split(",") if p.strip()]

    def match(name: str, p: str) -> bool:
        return fnmatch.fnmatchcase(name, p) if any(ch in p for ch in "*?[") else p in name

    return [c for c in cases if any(match(c.name, p) for p in pats)]


def run(args) -> tuple[dict, int]:
    """Run the suite for parsed ``args``; returns the JSON document and the exit status."""
    for out in (args.json, args.plot):
        if out:
            check_output_path(out)  # fail now, not after a 15-minute run
    if args.repeats is not None and args.repeats < 2:
        raise JaxgestError(f"--repeats must be at least 2, got {args.repeats}")
    harness.configure_jax()
    t0 = time.perf_counter()
    cases = [c for c in all_cases(quick=args.quick) if c.quick or not args.quick]
    cases = select(cases, args.cases)
    if not cases:
        raise JaxgestError(f"no benchmark case matches {args.cases!r}")
    if importlib.util.find_spec("torch") is None:
        print("torch not installed: PyTorch peers skipped", flush=True)
    probe = machine.probe_machine(1.0)
    info = machine.machine_info(probe)
    repeats = args.repeats or (QUICK_REPEATS if args.quick else FULL_REPEATS)
    budget = QUICK_BUDGET_S if args.quick else FULL_BUDGET_S
    print(f"# jaxgest benchmarks on {info['cpu']} ({info['cores']} cores), jax {info['jax']}, "
          f"{len(cases)} cases", flush=True)
    print(f"# probe: GEMM {probe['gemm_gflops']:.1f} GFLOP/s, memory {probe['mem_gbps']:.1f} GB/s, "
          f"load {probe['load_avg_1m']}; XLA threads {info['xla_cpu_threads']}"
          + (f", torch {info['torch']['version']} threads {info['torch']['threads']}" if info["torch"] else ""),
          flush=True)
    records, failures = [], []
    for case in cases:
        try:
            records.extend(harness.run_case(case, repeats=repeats, budget_s=budget, probe=probe,
                                            log=lambda s: print(s, flush=True)))
        except harness.EqualityError as e:
            print(f"  {case.name}: NOT TIMED, implementations disagree: {e}", flush=True)
            failures.append({"case": case.name, "error": str(e)})
    extras = {}
    if any(c.name.startswith("peer_zeggs") for c in cases):
        from jaxgest.bench.cases import peers

        frames = 600
        extras["weight_format_accuracy"] = acc = peers.format_accuracy(frames=frames)
        print(f"  weight formats after {frames} frames (RMS pose difference vs fp32, % of the pose range): "
              + ", ".join(f"{k} {v['rms_pct_of_range']:.3f} %" for k, v in acc.items() if isinstance(v, dict)),
              flush=True)
    info["load_avg_1m_end"] = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    run = {"cases": [c.name for c in cases], "quick": bool(args.quick), "repeats": repeats, "budget_s": budget}
    doc = {"stamp": provenance.stamp(run), "machine": info, "quick": bool(args.quick),
           "wall_s": time.perf_counter() - t0,
           "ratios": report.ratios(records), "peer_ratios": report.peer_ratios(records),
           "peer_compile_ratios": report.peer_compile_ratios(records),
           "failures": failures, "records": records, **extras}
    validate_document(doc)
    print()
    print(report.markdown_table(records))
    for extra in (report.ratio_table(records), report.peer_table(records), report.peer_compile_table(records),
                  report.floor_table(records),
                  report.compile_table(records)):
        if extra:
            print()
            print(extra)
    if args.json:
        write_text_atomic(args.json, json.dumps(doc, indent=2) + "\n")
        print(f"\nwrote {args.json}")
    if args.plot:
        if report.plot_scaling(records, args.plot):
            print(f"wrote {args.plot}")
        else:
            print(f"no case family spans several clip lengths: {args.plot} not written")
    print(f"total {doc['wall_s']:.1f} s")
    for f in failures:
        print(f"FAILED equality check: {f['error']}", file=sys.stderr)
    return doc, 1 if failures else 0


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return run(args)[1]
    except JaxgestError as e:
        print(f"jaxgest bench: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
