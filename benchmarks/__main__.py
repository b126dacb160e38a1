"""``python -m benchmarks [--quick] [--json OUT] [--plot OUT.png] [--cases SUBSTRING]``."""

from __future__ import annotations

import argparse
import json
import sys
import time


def build_parser(parser=None):
    parser = parser or argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer cases and repeats (< 2 minutes)")
    parser.add_argument("--json", metavar="OUT", help="write the records (SPEC §8) to this JSON file")
    parser.add_argument("--plot", metavar="OUT.png", help="per-pose cost against clip length")
    parser.add_argument("--cases", metavar="SUBSTRING", default=None,
                        help="only cases whose name contains this (comma-separated alternatives)")
    parser.add_argument("--repeats", type=int, default=None, help="timed repeats per implementation")
    return parser


def run(args) -> dict:
    from benchmarks import harness, report
    from benchmarks.cases import all_cases

    t0 = time.perf_counter()
    info = harness.machine_info()
    print(f"# jaxgest benchmarks on {info['cpu']} ({info['cores']} cores), jax {info['jax']}", flush=True)
    cases = all_cases(quick=args.quick)
    if args.quick:
        cases = [c for c in cases if c.quick]
    if args.cases:
        pats = [p.strip() for p in args.cases.split(",") if p.strip()]
        cases = [c for c in cases if any(p in c.name for p in pats)]
    repeats = args.repeats or (3 if args.quick else 7)
    records = []
    for case in cases:
        records.extend(harness.run_case(case, repeats=repeats))
    for r in records:
        harness.validate_record(r)
    result = {"machine": info, "quick": bool(args.quick), "wall_s": time.perf_counter() - t0,
              "ratios": report.ratios(records), "records": records}
    print()
    print(report.markdown_table(records))
    if args.json:
        from jaxgest.io import write_text_atomic

        write_text_atomic(args.json, json.dumps(result, indent=2) + "\n")
        print(f"\nwrote {args.json}")
    if args.plot:
        if report.plot_scaling(records, args.plot):
            print(f"wrote {args.plot}")
    print(f"total {result['wall_s']:.1f} s")
    return result


def main(argv=None) -> int:
    run(build_parser().parse_args(argv))
    return 0


if __name__ == "__main__":
    sys.exit(main())
