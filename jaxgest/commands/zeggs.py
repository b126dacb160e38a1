"""``jaxgest zeggs train | generate | pca | evaluate | import-official`` (docs/design.md §6)."""

from __future__ import annotations

import json
import pathlib

from jaxgest.commands.common import add_train_arguments, overrides, training_data, watch_arguments
from jaxgest.runtime.errors import DataError, JaxgestError
from jaxgest.zeggs.config import PRESETS

AUTHORS_PRESETS = ("authors", "authors-tiny")  # jaxgest.zeggs.official.train.PRESETS (imported lazily)
from jaxgest.zeggs.claims import SPEECH_STYLES, SUBSTITUTES


def register(subparsers) -> None:
    p = subparsers.add_parser("zeggs", help="ZeroEGGS: speech-driven gestures with zero-shot style")
    sub = p.add_subparsers(dest="zeggs_command", metavar="COMMAND")
    p.set_defaults(func=lambda a: (p.print_help(), 2)[1])

    t = sub.add_parser("train", help="train (or resume) on a folder of BVH + WAV clips")
    add_train_arguments(
        t, presets=tuple(PRESETS) + AUTHORS_PRESETS, workdir_help="run folder (checkpoints, stats, metrics.jsonl)",
        data_help="folder: ZEGGS layout or manifest.csv with audio (default: the built-in synthetic data, "
        "written to W/synthetic-data)",
        steps_help="total training steps (default: the preset's, tiny 300, small 8000, paper 120000, "
        "authors 160000, authors-tiny 20)",
        ckpt_every=None, ckpt_help="checkpoint every N steps and at the end (default: a tenth of the steps, "
        "at least 50)")
    t.add_argument("--no-loudness", action="store_true",
                   help="use the speech as recorded (default: loudness-normalised to -20 LUFS, as the authors)")
    t.set_defaults(func=_train)

    g = sub.add_parser("generate", help="gestures for a speech file in the style of example clip(s)")
    g.add_argument("--workdir", required=True)
    g.add_argument("--audio", required=True, help="WAV/FLAC speech (any sample rate or channel count)")
    g.add_argument("--style", action="append", required=True,
                   help="style example BVH (repeat to blend); for an imported label-based model (v2) a style label")
    g.add_argument("--weights", default=None, help="blend weights, comma-separated, one per --style, used as "
                   "given (2,0 doubles the first style's embedding; default: the average)")
    g.add_argument("--normalize-weights", action="store_true",
                   help="divide the blend weights by their sum (which must then be positive)")
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--temperature", type=float, default=None,
                   help="style sampling temperature (default: the model's inference config, 1.0)")
    g.add_argument("--weight-format", default="fp32", choices=("fp32", "bf16", "int8"),
                   help="generator weight format (not the blend --weights): bf16 or int8 weight-only")
    g.add_argument("--pca-edit", action="append", default=[], metavar="K=DELTA",
                   help="move the style embedding along PCA component K by DELTA standard deviations")
    g.add_argument("--first-pose", default=None, metavar="BVH",
                   help="imported authors' models only: the clip whose frame 0 starts the motion (default: the last "
                   "style example; required by label-based v2)")
    g.add_argument("--out", required=True, help="output BVH (on the first style clip's skeleton)")
    g.set_defaults(func=_generate)

    o = sub.add_parser("import-official", help="import the ZeroEGGS authors' released models (a clone of their "
                       "repository with Git LFS files) into a workdir that generate reads")
    o.add_argument("--repo", required=True, metavar="DIR", help="clone of ubisoft/ubisoft-laforge-ZeroEGGS")
    o.add_argument("--version", required=True, choices=("v1", "v2"),
                   help="v1: example-based style encoder; v2: style labels")
    o.add_argument("--workdir", required=True, help="folder to write (official.json, weights, statistics)")
    o.set_defaults(func=_import_official)

    c = sub.add_parser("pca", help="fit a PCA of style embeddings (for --pca-edit)")
    c.add_argument("--workdir", required=True)
    c.add_argument("--data", required=True)
    c.add_argument("--window", type=float, default=4.0, help="style window in seconds")
    c.set_defaults(func=_pca)

    e = sub.add_parser("evaluate", help="style probe, beat alignment vs shuffled control, Fréchet distance; "
                       "--claims: the paper's claims on generated motion against GT and MM")
    e.add_argument("--workdir", required=True)
    e.add_argument("--data", required=True)
    e.add_argument("--json", required=True, metavar="OUT.json")
    e.add_argument("--max-clips", type=int, default=None)
    e.add_argument("--seed", type=int, default=0)
    e.add_argument("--probe-data", nargs="+", default=[], metavar="DIR",
                   help="also probe on these dataset folders pooled (same folds; CIs over clips and datasets)")
    e.add_argument("--probe-seeds", type=int, default=0, metavar="N",
                   help="also probe on N built-in synthetic datasets (synth seeds 1..N, new scripts; generated "
                   "in a temporary folder) pooled with --probe-data")
    e.add_argument("--no-generation", action="store_true",
                   help="probes and leakage only (skip beat alignment and the Fréchet distance)")
    e.add_argument("--html", default=None, metavar="DIR",
                   help="also write 3D viewer pages of the best, median and worst generated test clips "
                   "(DIR/best.html, ...; ranked by BeatAlign minus its shuffled control), each playing the "
                   "clip's speech")
    e.add_argument("--claims", action="store_true",
                   help="the paper's claims on the generated motion instead of the diagnostics: style portrayal, "
                   "realism and appropriateness against GT and MM on --heldout data (zero-shot for the model's "
                   "exclude_styles), real speech with --speech; --data is the training-script data; writes a "
                   "stamped results file")
    e.add_argument("--heldout", nargs="+", default=[], metavar="DIR",
                   help="with --claims: held-out script datasets (e.g. jaxgest synth --seed K, K >= 1)")
    e.add_argument("--heldout-seeds", type=int, default=0, metavar="N",
                   help="with --claims: also the built-in synthetic data of seeds 1..N (generated in a temporary "
                   "folder) as held-out datasets")
    e.add_argument("--speech", nargs="+", default=[], metavar="WAV",
                   help="with --claims: real speech files to generate from (criterion 5)")
    e.add_argument("--speech-styles", default=",".join(SPEECH_STYLES), metavar="A,B",
                   help="with --speech: the styles to generate in (comma-separated)")
    e.add_argument("--segment-seconds", type=float, default=10.0,
                   help="with --speech: length of the speech segments (the units of the intervals)")
    e.add_argument("--substitute", default=None, choices=SUBSTITUTES,
                   help="with --claims: replace the generated motion by real motion (a check of the evaluation: "
                   "gt must hold, mm-style fails style portrayal, mm-script fails appropriateness)")
    e.add_argument("--style-scale", type=float, default=1.0, metavar="A",
                   help="with --claims: generate with every style embedding times A (the paper's scaling of "
                   "style embeddings; 1 = as trained)")
    e.set_defaults(func=_evaluate)


def _train_authors(args) -> int:
    """``--preset authors | authors-tiny``: the authors' network on their representation and objective
    (:mod:`jaxgest.zeggs.official.train`)."""
    from jaxgest.zeggs.official.train import train

    unsupported = [flag for flag, on in (("--override", args.override), ("--devices", args.devices),
                                         ("--no-loudness", args.no_loudness), ("--eval-every", args.eval_every),
                                         ("--eval-data", args.eval_data), ("--tb", args.tb),
                                         ("--profile", args.profile)) if on]
    if unsupported:
        raise JaxgestError(f"--preset {args.preset} (the authors' network) does not take {', '.join(unsupported)} "
                           "yet; the jaxgest presets (tiny, small, paper) do")
    data = training_data(args)
    r = train(data, args.workdir, preset=args.preset, steps=args.steps, seed=args.seed, ckpt_every=args.ckpt_every,
              log_every=args.log_every)
    if r["start_step"] >= r["steps"]:
        print(f"zeggs: {args.workdir} is already trained to step {r['start_step']} (>= --steps {r['steps']}); "
              "nothing to do (raise --steps to continue)")
        return 0
    print(f"zeggs: trained the authors' network {r['steps']} steps (resumed from {r['start_step']}) in "
          f"{r['wall_s']:.1f} s; final loss {r['final'].get('loss', float('nan')):.4g}; workdir {args.workdir} "
          "(generate with: jaxgest zeggs generate)")
    return 0


def _train(args) -> int:
    from jaxgest.runtime.config import apply_overrides
    from jaxgest.zeggs.config import preset
    from jaxgest.zeggs.trainer import DATA_FIELDS, train

    if args.preset in AUTHORS_PRESETS:
        return _train_authors(args)
    changes = {**overrides(args), **({"model.loudness": False} if args.no_loudness else {})}
    apply_overrides(preset(args.preset), changes, model="ZeroEGGS", forbidden=DATA_FIELDS)  # a bad one writes nothing
    data = training_data(args)  # steps and intervals checked before any data is written
    r = train(data, args.workdir, preset=args.preset, steps=args.steps,
              seed=args.seed, devices=args.devices, ckpt_every=args.ckpt_every, log_every=args.log_every,
              overrides=changes, **watch_arguments(args))
    final = r["final"]
    if r["start_step"] >= r["steps"]:
        if r["start_step"] == 0:
            print(f"zeggs: data checked and {args.workdir} prepared; no steps requested (--steps 0)")
        else:
            print(f"zeggs: {args.workdir} is already trained to step {r['start_step']} (>= --steps {r['steps']}); "
                  "nothing to do (raise --steps to continue)")
        return 0
    print(f"zeggs: trained {r['steps']} steps (resumed from {r['start_step']}) on {r['devices']} device(s) in "
          f"{r['wall_s']:.1f} s; final loss {final.get('loss', float('nan')):.4g}"
          + (f" (held-out {final['eval_loss']:.4g})" if "eval_loss" in final else "") + f"; workdir {args.workdir}")
    return 0


def _parse_weights(text):
    if text is None:
        return None
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise JaxgestError(f"--weights {text!r}: expected comma-separated numbers, e.g. 0.5,0.5") from None


def _generate(args) -> int:
    from jaxgest.runtime.io import check_output_path
    from jaxgest.motion import bvh
    from jaxgest.zeggs.inference import load_model
    from jaxgest.zeggs.official import is_official, load as load_official
    from jaxgest.zeggs.pca import parse_edits

    out = check_output_path(args.out)
    weights = _parse_weights(args.weights)
    edits = parse_edits(args.pca_edit)
    official = load_official(args.workdir) if is_official(args.workdir) else None
    labels = official is not None and not official.example_based
    styles = list(args.style) if labels else [bvh.load(s) for s in args.style]
    if not pathlib.Path(args.audio).is_file():
        raise JaxgestError(f"{args.audio}: no such audio file")
    extra = {}
    if official is not None:
        model = official
        extra["first_pose"] = bvh.load(args.first_pose) if args.first_pose else None
    elif args.first_pose:
        raise JaxgestError("--first-pose is for imported authors' models (zeggs import-official); this model "
                           "starts from the first style clip")
    else:
        model = load_model(args.workdir)
    motion = model.generate(args.audio, styles, weights=weights, seed=args.seed, temperature=args.temperature,
                            pca_edits=edits, name=out.stem, normalize_weights=args.normalize_weights,
                            weight_format=args.weight_format, **extra)
    bvh.save(motion, out)
    print(f"zeggs: wrote {out} ({motion.num_frames} frames at {motion.fps:g} fps, "
          f"{motion.skeleton.num_joints} joints)")
    return 0


def _import_official(args) -> int:
    from jaxgest.zeggs.official import import_release

    release = import_release(args.repo, args.version, args.workdir)
    m = release.manifest
    style = "example clips (style encoder)" if release.example_based else f"labels: {', '.join(m['label_names'])}"
    print(f"zeggs: imported {m['name']} into {args.workdir} ({len(m['bone_names'])} joints at {m['fps']:g} fps; "
          f"style from {style}); generate with: jaxgest zeggs generate --workdir {args.workdir} ...")
    return 0


def _pca(args) -> int:
    import numpy as np

    from jaxgest.motion.datasets import load_folder
    from jaxgest.zeggs.inference import load_model
    from jaxgest.zeggs.pca import fit_pca
    from jaxgest.zeggs.probes import style_windows

    model = load_model(args.workdir)
    clips = load_folder(args.data)
    emb = np.concatenate([style_windows(model, c, args.window) for c in clips])
    pca = fit_pca(emb)
    pca.save(pathlib.Path(args.workdir) / "pca.json")
    ev = ", ".join(f"{100 * r:.1f}%" for r in pca.explained_variance_ratio[:5])
    print(f"zeggs pca: {len(emb)} style windows from {len(clips)} clips; explained variance of the first "
          f"components: {ev}; saved {pathlib.Path(args.workdir) / 'pca.json'}")
    return 0


def _evaluate(args) -> int:
    from jaxgest.runtime.io import check_output_path, write_text_atomic
    from jaxgest.zeggs.evaluate import evaluate, markdown

    out = check_output_path(args.json)
    claims_only = [flag for flag, on in (("--heldout", args.heldout), ("--heldout-seeds", args.heldout_seeds),
                                         ("--speech", args.speech), ("--substitute", args.substitute),
                                         ("--style-scale", args.style_scale != 1.0)) if on]
    if args.claims:
        return _evaluate_claims(args, out)
    if claims_only:
        raise JaxgestError(f"{', '.join(claims_only)}: only with --claims")
    html_dir = None
    if args.html:
        from jaxgest.viewer import prepare_html_dir

        if args.no_generation:
            raise DataError("--html shows generated clips; it cannot go with --no-generation")
        html_dir = prepare_html_dir(args.html)
    model = None
    if html_dir is not None:  # loaded (and compiled) once, for the evaluation and the pages
        from jaxgest.zeggs.inference import load_model

        model = load_model(args.workdir)
    result = evaluate(args.workdir, args.data, seed=args.seed, max_clips=args.max_clips, model=model,
                      probe_data=args.probe_data, probe_seeds=args.probe_seeds,
                      generation=not args.no_generation)
    write_text_atomic(out, json.dumps(result, indent=2) + "\n")
    print(markdown(result))
    if html_dir is not None:
        from jaxgest.motion.datasets import load_folder
        from jaxgest.viewer import zeggs_evaluation_pages

        pages = zeggs_evaluation_pages(result, model, load_folder(args.data), html_dir,
                                       seed=args.seed)
        print("\n3D viewer pages: " + ", ".join(str(p) for p in pages))
    return 0


def _evaluate_claims(args, out) -> int:
    from jaxgest.runtime.provenance import write_results
    from jaxgest.zeggs import claims_run

    other = [flag for flag, on in (("--probe-data", args.probe_data), ("--probe-seeds", args.probe_seeds),
                                   ("--no-generation", args.no_generation), ("--max-clips", args.max_clips)) if on]
    if other:
        raise JaxgestError(f"{', '.join(other)}: not with --claims (diagnostics: run evaluate without --claims)")
    styles = tuple(s.strip() for s in args.speech_styles.split(",") if s.strip())
    if args.speech and not styles:
        raise JaxgestError(f"--speech-styles {args.speech_styles!r}: expected comma-separated style names")
    result, config = claims_run.run(args.workdir, args.data, heldout=args.heldout, heldout_seeds=args.heldout_seeds,
                                speech=args.speech, speech_styles=styles, segment_s=args.segment_seconds,
                                seed=args.seed, substitute=args.substitute, style_scale=args.style_scale)
    write_results(out, result, config, workdir=args.workdir)
    print(claims_run.markdown(result))
    return 0
