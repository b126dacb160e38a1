"""``jaxgest tgst train | transfer | evaluate`` (docs/design.md §6)."""

from __future__ import annotations

import pathlib

from jaxgest.commands.common import add_train_arguments, overrides, training_data, watch_arguments
from jaxgest.runtime.errors import DataError
from jaxgest.tgst.config import PRESETS, STYLE_INPUTS, InferenceConfig
from jaxgest.tgst.model import METHODS


def register(subparsers) -> None:
    p = subparsers.add_parser("tgst", help="tokenized gesture style transfer (Kuriyama et al. 2022)")
    sub = p.add_subparsers(dest="tgst_command", metavar="COMMAND")
    p.set_defaults(func=lambda a: (p.print_help(), 2)[1])

    t = sub.add_parser("train", help="train (or resume) the autoencoder, then the style transformer")
    add_train_arguments(
        t, presets=PRESETS, workdir_help="run folder (config.json, checkpoints, metrics.jsonl)",
        data_help="folder: Bandai-Namco files, ZEGGS layout or manifest.csv (default: the built-in synthetic "
        "data, written to W/synthetic-data)",
        steps_help="steps of EACH stage (default: the preset's train.autoencoder.steps and "
        "train.transformer.steps); see also --ae-steps")
    t.add_argument("--ae-steps", type=int, default=None, help="autoencoder steps (overrides --steps)")
    t.add_argument("--transformer-steps", type=int, default=None, help="transformer steps (overrides --steps)")
    t.add_argument("--ablate", default=None, metavar="TERM[,TERM]",
                   help="switch loss terms off (identity, cyclic, structure, appearance): paper Table 4")
    t.set_defaults(func=_train)

    x = sub.add_parser("transfer", help="perform a content clip in the style of a style clip")
    x.add_argument("--workdir", required=True, help="trained TGST workdir")
    x.add_argument("--content", required=True, metavar="C.bvh")
    x.add_argument("--style", required=True, metavar="S.bvh")
    x.add_argument("--out", required=True, metavar="O.bvh", help="output BVH (content's skeleton and length)")
    x.add_argument("--method", default=InferenceConfig.method, choices=METHODS,
                   help="soft swap (paper, default), hard swap, AdaIN or Avatar-net baselines; coherent (not in "
                   "the paper: one constant-rate path through the style, for an exemplar of the same gesture or "
                   "its mirror); autoencoder (the content's round trip)")
    x.add_argument("--style-input", default="mirror", choices=STYLE_INPUTS,
                   help="style clip the model is given: the exemplar followed by its mirror (default, the input "
                   "of the experiments' results) or as is")
    x.set_defaults(func=_transfer)

    register_evaluate(sub)


def _train(args) -> int:
    from jaxgest.tgst.trainer import apply_overrides, format_summary, resolve_preset, train

    ae = args.ae_steps if args.ae_steps is not None else args.steps
    tr = args.transformer_steps if args.transformer_steps is not None else args.steps
    ablate = tuple(a.strip() for a in args.ablate.split(",") if a.strip()) if args.ablate else ()
    changes = overrides(args)
    apply_overrides(resolve_preset(args.preset), changes)  # a bad override writes nothing
    summary = train(training_data(args), args.workdir, preset=args.preset, ae_steps=ae, transformer_steps=tr,
                    seed=args.seed, devices=args.devices, ckpt_every=args.ckpt_every, log_every=args.log_every,
                    ablate=ablate, overrides=changes, **watch_arguments(args))
    print(format_summary(summary))
    return 0


def _transfer(args) -> int:
    from jaxgest.runtime.io import check_output_path
    from jaxgest.motion import bvh
    from jaxgest.tgst.api import load_model

    out = check_output_path(args.out)
    for path in (args.content, args.style):
        if not pathlib.Path(path).is_file():
            raise DataError(f"{path}: no such file")
    # named by their paths so that errors about either clip name the file
    content = bvh.load(args.content).replace(name=str(args.content))
    style = bvh.load(args.style).replace(name=str(args.style))
    model = load_model(args.workdir)
    result = model.transfer(content, style, method=args.method, name=out.stem, style_input=args.style_input)
    bvh.save(result, out)
    given = "its mirror appended" if args.style_input == "mirror" else "as is"
    print(f"tgst: wrote {out} ({result.num_frames} frames at {result.fps:g} fps, {args.method} swap of "
          f"{pathlib.Path(args.content).name} in the style of {pathlib.Path(args.style).name}, {given})")
    return 0


def _evaluate(args) -> int:
    from jaxgest.runtime.io import check_output_path
    from jaxgest.tgst.evaluate import (diagnostics_table, evaluate, markdown_table, metric_validity,
                                       validity_table)
    from jaxgest.runtime.training import write_json_atomic

    check_output_path(args.json)
    html_dir = None
    if args.html:
        from jaxgest.viewer import prepare_html_dir

        html_dir = prepare_html_dir(args.html)
    methods = None if args.methods is None else tuple(m.strip() for m in args.methods.split(",") if m.strip())
    contents = None if args.contents is None else [c.strip() for c in args.contents.split(",") if c.strip()]
    model = None
    if html_dir is not None:  # loaded (and compiled) once, for the evaluation and the pages
        from jaxgest.tgst.api import load_model

        model = load_model(args.workdir)
    report = evaluate(
        args.workdir,
        args.data,
        model=model,
        pairs=args.pairs,
        methods=methods,
        max_pairs=args.max_pairs,
        contents=contents,
        seed=args.seed,
        protocol=args.protocol,
        trim_seconds=args.trim,
        bucket=args.bucket,
        style_input=args.style_input,
    )
    if args.validity:
        report["metric_validity"] = metric_validity(
            args.data,
            pairs="inter" if args.pairs == "intra" else args.pairs,
            max_pairs=args.max_pairs,
            contents=contents,
            seed=args.seed,
            protocol=args.protocol,
            trim_seconds=args.trim,
        )
    write_json_atomic(args.json, report)
    t = report["timing"]
    print(f"{report['pairs']} pairs: {report['num_pairs']} (data {report['data']}); protocol "
          f"{report['protocol']['name']}; {t['wall_s']:.0f} s wall, {t['cpu_s']:.0f} s CPU")
    print(markdown_table(report))
    short = sum(1 for r in report["per_pair"]
                if any("too short" in e.get("skipped", "") or "shorter than one style window" in e.get("skipped", "")
                       for e in r["errors"].values()))
    if short:
        cut = report["protocol"]["trim_seconds"]
        need = f"its {cut:g} s cut at both ends plus one style window" if cut else "one style window"
        print(f"\n{short} of {report['num_pairs']} pairs skipped: a clip is too short for "
              f"{need} ({report['protocol']['name']} protocol; per-pair reasons in the JSON"
              f"{'; --trim SECONDS shortens the cut' if cut else ''})")
    diag = diagnostics_table(report)
    if diag:
        print()
        print(diag)
    if args.validity:
        print()
        print(validity_table(report["metric_validity"]))
    if html_dir is not None:
        from jaxgest.motion.datasets import load_folder
        from jaxgest.viewer import tgst_evaluation_pages

        pages = tgst_evaluation_pages(report, model, load_folder(args.data, progress=False),
                                      html_dir)
        print("\n3D viewer pages: " + ", ".join(str(p) for p in pages))
    return 0


def register_evaluate(tgst_subparsers) -> None:
    """Add ``evaluate`` to the ``jaxgest tgst`` subcommands (docs/design.md §6): paper Tables 2-3 (and 1)."""
    from jaxgest.tgst.evaluate import DEFAULT_BUCKET, EVALUATE_METHODS, PAIR_MODES, PROTOCOLS

    p = tgst_subparsers.add_parser(
        "evaluate", help="content/style errors of style transfers (paper Tables 2-3)"
    )
    p.add_argument("--workdir", required=True, help="trained TGST workdir")
    p.add_argument("--data", required=True, help="dataset folder (Bandai-Namco, ZEGGS or manifest.csv)")
    p.add_argument("--json", required=True, help="output JSON file")
    p.add_argument("--pairs", choices=PAIR_MODES, default="intra", help="intra-, inter-scenario or all pairs")
    p.add_argument("--methods", default=None,
                   help=f"comma-separated methods (default: {','.join(EVALUATE_METHODS)}: the paper's four and "
                   "the coherent swap, not in the paper; also: autoencoder)")
    p.add_argument("--protocol", choices=tuple(PROTOCOLS), default="authors",
                   help="authors (default, paper tables): root-local positions, forward differences, 1 s cut at "
                   "both ends, mirrored style appended; world: world positions, no cut, no mirror")
    p.add_argument("--style-input", default="mirror", choices=STYLE_INPUTS,
                   help="style clip the model is given: followed by its mirror (default, as the authors' "
                   "evaluator and tgst transfer) or as is (the input of the Bandai-Namco-1 results)")
    p.add_argument("--trim", type=float, default=None, metavar="SECONDS",
                   help="override the protocol's cut at both ends (authors: 1 s); named in the report")
    p.add_argument("--max-pairs", type=int, default=None,
                   help="evaluate a seeded random subset of pairs (0 or omitted: all pairs)")
    p.add_argument("--contents", default=None, help="comma-separated content labels of the content clips")
    p.add_argument("--seed", type=int, default=0, help="seed of the pair subset")
    p.add_argument("--bucket", type=float, default=DEFAULT_BUCKET,
                   help=f"length-bucket ratio of the batched transfers (default {DEFAULT_BUCKET}; "
                   "1 = exact per-pair shapes, one compilation per pair)")
    p.add_argument(
        "--validity",
        action="store_true",
        help="also compute the metric-validity table (paper Table 1) of the data (inter pairs for --pairs intra)",
    )
    p.add_argument("--html", default=None, metavar="DIR",
                   help="also write 3D viewer pages of the best, median and worst pairs (DIR/best.html, ...; "
                   "ranked by the first method's content + style error, each over its median)")
    p.set_defaults(func=_evaluate)
