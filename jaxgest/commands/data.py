"""``jaxgest synth`` and ``jaxgest render`` (docs/design.md §6): built-in data and stick-figure animations."""

from __future__ import annotations

import pathlib

from jaxgest.runtime.errors import DataError


def register(subparsers) -> None:
    p = subparsers.add_parser("synth", help="write the built-in synthetic dataset (BVH + WAV + manifest.csv)")
    p.add_argument("--out", required=True, help="output folder (created if missing)")
    p.add_argument("--clips", type=int, default=None,
                   help="number of clips (default: every content in every style, 6 x 7 = 42)")
    p.add_argument("--seed", type=int, default=0, help="seed of the scripts and performances")
    p.add_argument("--seconds", type=float, default=10.0, help="clip length in seconds")
    p.set_defaults(func=_synth)

    r = subparsers.add_parser("render",
                              help="3D HTML viewer, stick-figure GIF or PNG still of BVH files, side by side")
    r.add_argument("inputs", nargs="+", metavar="IN.bvh")
    r.add_argument("--out", required=True,
                   help="output .html (self-contained 3D viewer), .gif (animation) or .png (still; --png "
                   "still works)")
    r.add_argument("--titles", default=None, help="comma-separated panel titles (default: file stems)")
    r.add_argument("--png", action="store_true", help="write a still of the middle frame instead")
    r.add_argument("--frame", type=int, default=None, help="frame of the --png still")
    r.add_argument("--fps", type=float, default=None, help="GIF frame rate (default min(clip fps, 20))")
    r.add_argument("--max-seconds", type=float, default=None, help="render at most this many seconds")
    r.add_argument("--overlay", action="store_true", help="HTML: start with the clips overlaid in one panel")
    r.add_argument("--trails", type=float, default=None, metavar="SECONDS",
                   help="HTML: start with hand trajectories over the last SECONDS shown")
    r.add_argument("--audio", default=None, metavar="A.wav",
                   help="HTML: speech to play with the motion (any sound file soundfile reads; embedded as 16 kHz "
                   "mono Ogg Opus, its clock leads the playback)")
    r.add_argument("--audio-offset", type=float, default=0.0, metavar="S",
                   help="HTML: seconds into the audio at the motion's first frame (negative: the speech starts "
                   "S seconds later; default 0)")
    r.set_defaults(func=_render)


def _synth(args) -> int:
    from jaxgest.motion.synthetic import write_dataset

    manifest = write_dataset(args.out, clips=args.clips, seed=args.seed, seconds=args.seconds)
    print(manifest)
    return 0


OUT_KINDS = {".html": "html", ".htm": "html", ".gif": "gif", ".png": "png"}


def _render(args) -> int:
    from jaxgest.motion import bvh
    from jaxgest.render import render_gif, render_png

    suffix = pathlib.Path(args.out).suffix.lower()
    kind = OUT_KINDS.get(suffix)
    if kind is None:
        raise DataError(f"{args.out}: unknown output type {suffix or '(no extension)'!r}; "
                        "use .html (3D viewer), .gif (animation) or .png (still)")
    if args.png and kind != "png":
        raise DataError(f"{args.out}: --png writes a PNG still; name the output .png")
    if args.audio is not None and kind != "html":
        raise DataError(f"{args.out}: --audio plays speech in the HTML viewer; name the output .html")
    if args.audio is None and args.audio_offset:
        raise DataError("--audio-offset without --audio: name the speech file with --audio A.wav")
    if args.audio is not None and not pathlib.Path(args.audio).is_file():
        raise DataError(f"{args.audio}: no such audio file")
    motions = []
    for path in args.inputs:
        if not pathlib.Path(path).is_file():
            raise DataError(f"{path}: no such file")
        motions.append(bvh.load(path))
    titles = args.titles.split(",") if args.titles else [pathlib.Path(p).stem for p in args.inputs]
    if len(titles) != len(motions):
        raise DataError(f"--titles has {len(titles)} entries for {len(motions)} input files")
    if kind == "html":
        from jaxgest.viewer import render_html

        out = render_html(motions, args.out, titles=titles, overlay=args.overlay,
                          trails=args.trails is not None,
                          trail_seconds=1.0 if args.trails is None else args.trails,
                          audio=args.audio, audio_offset=args.audio_offset)
    elif kind == "png":
        out = render_png(motions, args.out, frame=args.frame, titles=titles)
    else:
        out = render_gif(motions, args.out, titles=titles, fps=args.fps, max_seconds=args.max_seconds)
    print(out)
    return 0
