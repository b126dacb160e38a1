"""``jaxgest demo`` (the main job) and ``jaxgest pipeline`` (speech -> gestures -> style), docs/design.md §6.

The demo runs everything on the built-in synthetic data, with no download and no GPU:

1. writes the synthetic dataset (BVH + WAV + manifest.csv);
2. trains tiny TGST (autoencoder, then transformer) and tiny ZeroEGGS models;
3. style-transfers a neutral clip to two expressive styles with all four methods (soft, hard, AdaIN,
   Avatar-net), with content / style / ground-truth errors (the synthetic data has the exact ground truth);
4. generates gestures from a synthetic speech WAV in two styles and a 50/50 blend, with beat alignment
   against a shuffled-onset control, and the style-probe accuracy of the ZEGGS style embeddings;
5. runs the chained pipeline (speech -> ZEGGS in the neutral style -> TGST to an expressive style);
6. writes BVH files, side-by-side GIFs with titles and a self-contained 3D HTML viewer page beside each GIF
   (:mod:`jaxgest.viewer`; whole clips, not only the GIF's first seconds; the speech pages play their speech),
   ``metrics.json`` and prints a summary table naming the pages.

``--quick`` (CI smoke test, about 2 minutes on 2 cores) uses 2 contents x 7 styles of 6 s and few training
steps; the default (about 10 minutes) uses all 6 contents x 7 styles of 10 s and longer training. The tiny
models are not the papers' sizes and the numbers are a smoke check, not results: the experiments in
``experiments/`` hold the real ones.
"""

from __future__ import annotations

import json
import pathlib
import time

from jaxgest.runtime.errors import DataError
from jaxgest.tgst.config import STYLE_INPUTS
from jaxgest.tgst.model import METHODS

#: (synthetic clips, seconds, TGST AE steps, TGST transformer steps, ZEGGS steps, GIF seconds)
PLANS = {
    "quick": dict(clips=14, seconds=6.0, ae_steps=400, transformer_steps=200, zeggs_steps=200, gif_seconds=4.0),
    "full": dict(clips=42, seconds=10.0, ae_steps=6000, transformer_steps=4000, zeggs_steps=4000, gif_seconds=6.0),
}
CONTENT, OTHER_CONTENT = "greeting", "directions"  # first two contents of the plan (content-major)
NEUTRAL, STYLES = "neutral", ("energetic", "sad")
#: metric protocol of the transfer table (jaxgest.tgst.evaluate.PROTOCOLS; the paper tables' default)
TRANSFER_PROTOCOL = "authors"


def register(subparsers) -> None:
    d = subparsers.add_parser("demo", help="train tiny models on built-in data, transfer, generate, chain (main job)")
    d.add_argument("--out", default="jaxgest-demo", help="output folder (default: ./jaxgest-demo)")
    d.add_argument("--quick", action="store_true", help="smaller data and training (about 2 minutes)")
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--style-input", default="mirror", choices=STYLE_INPUTS,
                   help="style clip the TGST model is given: the exemplar followed by its mirror (default, the "
                   "experiments' input) or as is")
    d.set_defaults(func=_demo)

    p = subparsers.add_parser("pipeline", help="speech -> ZeroEGGS gestures -> TGST style transfer")
    p.add_argument("--audio", required=True, metavar="A.wav")
    p.add_argument("--zeggs-workdir", required=True, metavar="W1")
    p.add_argument("--tgst-workdir", required=True, metavar="W2")
    p.add_argument("--style", required=True, metavar="S.bvh", help="style exemplar (the output's skeleton)")
    p.add_argument("--zeggs-style", default=None, metavar="N.bvh",
                   help="style clip for ZeroEGGS, e.g. a neutral one (default: the --style exemplar)")
    p.add_argument("--method", default="soft", choices=METHODS)
    p.add_argument("--style-input", default="mirror", choices=STYLE_INPUTS,
                   help="style clip TGST is given: the exemplar followed by its mirror (default) or as is")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--temperature", type=float, default=1.0)
    p.add_argument("--out", required=True, metavar="O.bvh")
    p.set_defaults(func=_pipeline)


def _load_bvh(path):
    from jaxgest.motion import bvh

    if not pathlib.Path(path).is_file():
        raise DataError(f"{path}: no such file")
    return bvh.load(path)


def _pipeline(args) -> int:
    from jaxgest.runtime.io import check_output_path
    from jaxgest.motion import bvh
    from jaxgest.pipeline import speech_to_styled_gestures

    out = check_output_path(args.out)
    if not pathlib.Path(args.audio).is_file():
        raise DataError(f"{args.audio}: no such audio file")
    style = _load_bvh(args.style)
    zstyle = _load_bvh(args.zeggs_style) if args.zeggs_style else None
    styled, _, t = speech_to_styled_gestures(args.audio, style, zeggs_workdir=args.zeggs_workdir,
                                             tgst_workdir=args.tgst_workdir, zeggs_style=zstyle,
                                             method=args.method, seed=args.seed, temperature=args.temperature,
                                             style_input=args.style_input)
    bvh.save(styled.replace(name=out.stem), out)
    print(f"pipeline: wrote {out} ({styled.num_frames} frames at {styled.fps:g} fps on the style's skeleton; "
          f"zeggs {t['zeggs_s']:.1f} s, tgst {t['tgst_s']:.1f} s)")
    return 0


# ------------------------------------------------------------------------------------------------------
# demo


def _clip(data: pathlib.Path, content: str, style: str):
    from jaxgest.motion import bvh

    path = data / f"{content}_{style}_0.bvh"
    if not path.is_file():
        raise DataError(f"{path}: missing from the demo data")
    return bvh.load(path), path


def _round(x, nd=4):
    if isinstance(x, dict):
        return {k: _round(v, nd) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_round(v, nd) for v in x]
    if isinstance(x, float):
        return round(x, nd)
    return x


def run_demo(out, *, quick: bool = False, seed: int = 0, progress: bool = True, style_input: str = "mirror") -> dict:
    """Run the whole demo into ``out``; returns the metrics dict (also written to ``out/metrics.json``).
    ``style_input``: what the TGST transfers are given as the style clip (``TGSTModel.transfer``)."""
    from jaxgest.runtime.io import check_output_path
    from jaxgest.motion import bvh
    from jaxgest.audio import load_audio
    from jaxgest.motion.datasets import load_folder
    from jaxgest.motion.synthetic import write_dataset
    from jaxgest.pipeline import speech_to_styled_gestures
    from jaxgest.render import render_gif
    from jaxgest.viewer import render_html
    from jaxgest.tgst import evaluate as tev
    from jaxgest.tgst.api import load_model as load_tgst
    from jaxgest.tgst.trainer import train as train_tgst
    from jaxgest.runtime.training import write_json_atomic
    from jaxgest.zeggs import evaluate as zev
    from jaxgest.zeggs.inference import load_model as load_zeggs
    from jaxgest.zeggs.trainer import train as train_zeggs

    plan = PLANS["quick" if quick else "full"]
    out = pathlib.Path(out)
    check_output_path(out / "metrics.json") if out.exists() else out.mkdir(parents=True)
    data, results = out / "data", out / "results"
    results.mkdir(exist_ok=True)
    timings, t_all = {}, time.perf_counter()
    pages = []  # the HTML viewer pages written into results/

    def step(name):
        if progress:
            print(f"[demo] {name}", flush=True)
        return time.perf_counter()

    t = step(f"1/6 synthetic data: {plan['clips']} clips of {plan['seconds']:g} s -> {data}")
    write_dataset(data, clips=plan["clips"], seed=seed, seconds=plan["seconds"], progress=progress)
    timings["data_s"] = time.perf_counter() - t

    t = step("2/6 training TGST (tiny): autoencoder, then style transformer")
    tgst_summary = train_tgst(data, out / "tgst", preset="tiny", ae_steps=plan["ae_steps"],
                              transformer_steps=plan["transformer_steps"], seed=seed, progress=progress,
                              log_every=25, ckpt_every=max(plan["ae_steps"], plan["transformer_steps"]))
    timings["tgst_train_s"] = time.perf_counter() - t
    t = step("2/6 training ZeroEGGS (tiny)")
    zeggs_summary = train_zeggs(data, out / "zeggs", preset="tiny", steps=plan["zeggs_steps"], seed=seed,
                                progress=progress, log_every=20, ckpt_every=plan["zeggs_steps"])
    timings["zeggs_train_s"] = time.perf_counter() - t

    # ---- (a) style transfer of a neutral clip to two styles, all four methods
    t = step(f"3/6 style transfer: '{CONTENT}' ({NEUTRAL}) -> {', '.join(STYLES)}, "
             f"methods {', '.join(tev.TRANSFER_METHODS)}")
    tgst = load_tgst(out / "tgst")
    content, _ = _clip(data, CONTENT, NEUTRAL)
    transfer = {}
    for style_name in STYLES:
        style, _ = _clip(data, OTHER_CONTENT, style_name)  # another content: unaligned, inter-scenario
        truth, _ = _clip(data, CONTENT, style_name)  # the content performed in the style: ground truth
        panels, titles, per_method = [content, style], [f"content ({NEUTRAL})", f"style ({style_name})"], {}
        for method in tev.TRANSFER_METHODS:
            result = tgst.transfer(content, style, method=method, name=f"{CONTENT}_{style_name}_{method}",
                                   style_input=style_input)
            bvh.save(result, results / f"transfer_{style_name}_{method}.bvh")
            per_method[method] = dict(tev.clip_errors(result, content, style, truth, protocol=TRANSFER_PROTOCOL),
                                      protocol=TRANSFER_PROTOCOL)
            panels.append(result)
            titles.append(method)
        # controls under the same protocol: the content clip and the style clip themselves as the "result"
        for control, clip in (("content_as_is", content), ("style_as_is", style)):
            per_method[control] = dict(tev.clip_errors(clip, content, style, truth, protocol=TRANSFER_PROTOCOL),
                                       protocol=TRANSFER_PROTOCOL)
        panels.append(truth)
        titles.append("ground truth")
        render_gif(panels, results / f"transfer_{style_name}.gif", titles=titles, max_seconds=plan["gif_seconds"])
        render_html(panels, results / f"transfer_{style_name}.html", titles=titles,
                    heading=f"style transfer: '{CONTENT}' ({NEUTRAL}) -> {style_name}")
        pages.append(f"transfer_{style_name}.html")
        transfer[style_name] = per_method
    timings["transfer_s"] = time.perf_counter() - t

    # ---- (b) speech -> gestures in two styles and a 50/50 blend
    t = step(f"4/6 speech-driven generation: '{OTHER_CONTENT}' speech in {', '.join(STYLES)} and a 50/50 blend")
    zeggs = load_zeggs(out / "zeggs")
    wav = data / f"{OTHER_CONTENT}_{NEUTRAL}_0.wav"
    audio, sr = load_audio(wav)
    examples = [_clip(data, CONTENT, s)[0] for s in STYLES]
    generated, gen_metrics = [], {}
    for label, styles, weights in ((STYLES[0], examples[:1], None), (STYLES[1], examples[1:], None),
                                   ("blend 50/50", examples, [0.5, 0.5])):
        m = zeggs.generate(audio, styles, weights=weights, seed=seed, sr=sr, name=label.replace(" ", "_"))
        bvh.save(m, results / f"speech_{label.replace(' ', '_').replace('/', '-')}.bvh")
        try:
            gen_metrics[label] = zev.beat_scores(m, audio, sr, seed=seed)
        except DataError as e:
            gen_metrics[label] = {"skipped": str(e)}
        generated.append(m)
    render_gif(generated, results / "speech_styles.gif", titles=[STYLES[0], STYLES[1], "blend 50/50"],
               max_seconds=plan["gif_seconds"])
    render_html(generated, results / "speech_styles.html", titles=[STYLES[0], STYLES[1], "blend 50/50"],
                heading=f"ZeroEGGS: '{OTHER_CONTENT}' speech in {', '.join(STYLES)} and a 50/50 blend",
                trails=True, audio=(audio, sr))
    pages.append("speech_styles.html")
    clips = load_folder(data)
    try:  # the probe beside its controls (random-init encoder, raw window statistics) on the same folds
        probe = zev.probe(zeggs, clips)
        probe = {task: {k: {"accuracy": v["accuracy"], "ci95_half_width": v["clip_mean"]["ci95_half_width"],
                            "chance": v["chance"]} for k, v in probe[task].items() if k != "trained_minus"}
                 for task in ("style", "content")} | {"protocol": probe["protocol"]}
    except DataError as e:
        probe = {"skipped": str(e)}
    try:  # the leakage contrast: does a same-style example of other content beat another style's?
        lk = zev.leakage(zeggs, [c for c in clips if c.audio is not None])
        leakage = {"mean_loss": lk["mean_loss"], "contrasts": lk["contrasts"], "clips": lk["clips"]}
    except DataError as e:
        leakage = {"skipped": str(e)}
    timings["generate_s"] = time.perf_counter() - t

    # ---- (c) chained pipeline: speech -> ZEGGS (neutral) -> TGST (energetic)
    t = step(f"5/6 pipeline: speech -> ZeroEGGS ({NEUTRAL}) -> TGST ({STYLES[0]})")
    neutral_example, _ = _clip(data, CONTENT, NEUTRAL)
    exemplar, _ = _clip(data, CONTENT, STYLES[0])
    styled, zeggs_out, ptimes = speech_to_styled_gestures(audio, exemplar, zeggs_workdir=out / "zeggs",
                                                          tgst_workdir=out / "tgst", zeggs_style=neutral_example,
                                                          seed=seed, sr=sr, style_input=style_input)
    bvh.save(zeggs_out, results / "pipeline_zeggs_neutral.bvh")
    bvh.save(styled, results / f"pipeline_{STYLES[0]}.bvh")
    pipeline_titles = [f"ZeroEGGS ({NEUTRAL})", f"+ TGST ({STYLES[0]})", "style exemplar"]
    render_gif([zeggs_out, styled, exemplar], results / "pipeline.gif", titles=pipeline_titles,
               max_seconds=plan["gif_seconds"])
    render_html([zeggs_out, styled, exemplar], results / "pipeline.html", titles=pipeline_titles,
                heading=f"pipeline: speech -> ZeroEGGS ({NEUTRAL}) -> TGST ({STYLES[0]})", audio=(audio, sr))
    pages.append("pipeline.html")
    pipe = {"frames": styled.num_frames, "fps": styled.fps, **ptimes}
    try:
        pipe["beat_alignment"] = zev.beat_scores(styled, audio, sr, seed=seed)
    except DataError as e:
        pipe["beat_alignment"] = {"skipped": str(e)}
    timings["pipeline_s"] = time.perf_counter() - t
    timings["total_s"] = time.perf_counter() - t_all

    report = {
        "mode": "quick" if quick else "full", "seed": seed, "plan": plan, "style_input": style_input,
        "tgst_training": {k: tgst_summary[k] for k in ("ae", "transformer", "windows")},
        "zeggs_training": {k: v for k, v in zeggs_summary.items() if k in ("steps", "final", "wall_s")},
        "style_transfer": transfer,
        "generation": {"beat_alignment": gen_metrics, "style_probe": probe, "leakage": leakage},
        "pipeline": pipe,
        "timings_s": timings,
        "pages": pages,
        "notes": {
            "errors": "mean over frames; content = DTW hand error (m) vs the content clip, style = arm-velocity "
                      "window statistics error (m/s) vs the style clip, gt_* = vs the ground-truth clip; "
                      "content_as_is / style_as_is = the content / style clip itself as the result (controls); "
                      f"protocol '{TRANSFER_PROTOCOL}' (jaxgest tgst evaluate --protocol): root-local positions, "
                      "1 s cut at both ends, forward differences, style clip + its mirror",
            "beat_alignment": "BeatAlign of hand-speed minima vs audio onsets; 'shuffled' = circularly shifted "
                              "onsets (control)",
            "scale": "tiny models trained for a few minutes: a smoke check, not the papers' results",
        },
    }
    report = _round(report)
    write_json_atomic(out / "metrics.json", report)
    step("6/6 done")
    if progress:
        print(summary_table(report))
        print(f"\nwrote {results}/*.bvh, *.gif and {out / 'metrics.json'} in {timings['total_s']:.0f} s")
        print("3D viewer pages (open in a browser; no network needed):")
        for name in pages:
            print(f"  {results / name}")
    return report


def summary_table(report: dict) -> str:
    lines = ["", "style transfer of a neutral clip (errors: lower is better; gt = against the true clip; "
             "controls: the content / style clip as is)", "",
             "| style | method | protocol | content err (m) | style err (m/s) | gt content (m) | gt style (m/s) |",
             "|---|---|---|---:|---:|---:|---:|"]
    for style, per in report["style_transfer"].items():
        for method, e in per.items():
            label = method.replace("_as_is", " as is (control)")
            lines.append(f"| {style} | {label} | {e.get('protocol', '-')} | {e['content']['mean']:.3f} | "
                         f"{e['style']['mean']:.3f} | {e['gt_content']['mean']:.3f} | {e['gt_style']['mean']:.3f} |")
    lines += ["", "speech-driven generation (BeatAlign: higher is better)", "",
              "| style | BeatAlign | shuffled control |", "|---|---:|---:|"]
    for label, b in report["generation"]["beat_alignment"].items():
        if "aligned" in b:
            lines.append(f"| {label} | {b['aligned']:.3f} | {b['shuffled']:.3f} |")
        else:
            lines.append(f"| {label} | n/a | {b.get('skipped', '')} |")
    p = report["generation"]["style_probe"]
    if "style" in p:
        lines += ["", "ZeroEGGS style embeddings: linear probes (style: leave-one-content-out, content: "
                  "leave-one-style-out; ± 95 % CI over clips)", "",
                  "| probe | trained encoder | control: random init | control: raw window statistics | chance |",
                  "|---|---:|---:|---:|---:|"]
        for task in ("style", "content"):
            t = p[task]
            lines.append(f"| {task} | " + " | ".join(
                f"{t[k]['accuracy']:.2f} ± {t[k]['ci95_half_width']:.2f}" for k in ("trained", "random_init",
                                                                                   "raw_statistics"))
                + f" | {t['trained']['chance']:.2f} |")
    lk = report["generation"].get("leakage", {})
    if "contrasts" in lk:
        lines += ["", "ZeroEGGS leakage contrast (reconstruction loss of fixed targets; positive = the second "
                  "source is better; mean ± SE over clips)", ""]
        for name in ("other_style - same_style_other_content", "zero - same_style_other_content"):
            d = lk["contrasts"].get(name)
            if d:
                z = "n/a" if d["z"] is None else f"{d['z']:.1f}"
                lines.append(f"- {name.replace('_', ' ')}: {d['mean']:+.4f} ± {d['standard_error']:.4f} (z = {z})")
    t = report["timings_s"]
    lines.append(f"timings: data {t['data_s']:.0f} s, TGST training {t['tgst_train_s']:.0f} s, ZeroEGGS training "
                 f"{t['zeggs_train_s']:.0f} s, transfer {t['transfer_s']:.0f} s, generation {t['generate_s']:.0f} s, "
                 f"pipeline {t['pipeline_s']:.0f} s")
    return "\n".join(lines)


def _demo(args) -> int:
    run_demo(args.out, quick=args.quick, seed=args.seed, style_input=args.style_input)
    return 0
