"""Writing the built-in synthetic dataset to disk (BVH + 16 kHz WAV + manifest.csv)."""

from __future__ import annotations

import csv
import io
import itertools
import pathlib

from jaxgest.runtime.errors import DataError
from jaxgest.runtime.io import write_text_atomic
from jaxgest.motion.synthetic.clips import SAMPLE_RATE, render_clip
from jaxgest.motion.synthetic.content import CONTENTS
from jaxgest.motion.synthetic.styles import STYLES

MANIFEST_COLUMNS = ("path", "content", "style", "audio")


def clip_plan(clips=None, contents=None, styles=None):
    """The (content, style, take) triples of a dataset, content-major: the first clips show one content in
    every style, then the next content, ...; takes k >= 1 (new performance seeds) follow when ``clips``
    exceeds contents x styles. ``clips=None`` means every content in every style once."""
    contents = list(contents or CONTENTS)
    styles = list(styles or STYLES)
    grid = list(itertools.product(contents, styles))
    n = len(grid) if clips is None else int(clips)
    if n < 1:
        raise DataError(f"synth: --clips must be at least 1, got {n}")
    return [(c, s, k // len(grid)) for k, (c, s) in zip(range(n), itertools.cycle(grid))]


def write_dataset(out_dir, clips=None, seed: int = 0, fps: float = 60.0, seconds: float = 10.0,
                  progress: bool = True) -> pathlib.Path:
    """Render and write the built-in dataset; returns the path of ``manifest.csv``.

    Files: ``{content}_{style}_{k}.bvh`` (k = take), the matching ``.wav`` (16 kHz mono), and
    ``manifest.csv`` with columns path, content, style, audio (paths relative to ``out_dir``). The script
    (strokes, audio) of each content depends on ``seed``; the performance noise on ``seed`` and the take.
    """
    import soundfile as sf
    from tqdm import tqdm

    from jaxgest.motion import bvh

    out = pathlib.Path(out_dir)
    if out.exists() and not out.is_dir():
        raise DataError(f"{out}: exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise DataError(f"{out}: cannot create output directory ({e.strerror})") from None
    if seconds < 2.0:
        raise DataError(f"synth: clips must be at least 2 s long, got {seconds}")
    rows = []
    plan = clip_plan(clips)
    specs = {c: CONTENTS[c].with_seed(seed, seconds) for c in {p[0] for p in plan}}
    for content, style, take in tqdm(plan, desc="synth", unit="clip", disable=not progress):
        motion, audio, sr = render_clip(specs[content], style, seed=1000 * int(seed) + take, fps=fps,
                                        sr=SAMPLE_RATE)
        stem = f"{content}_{style}_{take}"
        motion = motion.replace(name=stem)
        bvh.save(motion, out / f"{stem}.bvh")
        sf.write(str(out / f"{stem}.wav"), audio, sr, subtype="PCM_16")
        rows.append({"path": f"{stem}.bvh", "content": content, "style": style, "audio": f"{stem}.wav"})
    manifest = out / "manifest.csv"
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=MANIFEST_COLUMNS)
    w.writeheader()
    w.writerows(rows)
    write_text_atomic(manifest, buf.getvalue())
    return manifest


def training_folder(data_dir, workdir, progress: bool = True) -> pathlib.Path:
    """The data folder of a training run: ``data_dir``, or (None) the built-in synthetic dataset written once
    to ``<workdir>/synthetic-data`` (reused on resume; written to a temporary folder and renamed, so several
    processes starting together do not read a half-written set). A workdir trained on another folder needs
    that folder to resume: raises :class:`DataError` instead of switching datasets silently."""
    import json
    import os
    import shutil

    if data_dir is not None:
        return pathlib.Path(data_dir)
    workdir = pathlib.Path(workdir)
    folder = workdir / "synthetic-data"
    config = workdir / "config.json"
    if config.is_file():
        try:
            recorded = json.loads(config.read_text()).get("data")
        except (OSError, ValueError):
            recorded = None
        if recorded and pathlib.Path(recorded).resolve() != folder.resolve():
            raise DataError(f"{workdir}: was trained on {recorded}; pass --data {recorded} to resume it "
                            "(without --data a train command uses the built-in synthetic data)")
    if not (folder / "manifest.csv").is_file():
        tmp = workdir / f".synthetic-data.tmp-{os.getpid()}"
        write_dataset(tmp, progress=progress)
        try:
            os.rename(tmp, folder)
        except OSError:  # another process was first
            shutil.rmtree(tmp, ignore_errors=True)
    if progress:
        print(f"jaxgest: no --data given: training on the built-in synthetic data in {folder}")
    return folder
