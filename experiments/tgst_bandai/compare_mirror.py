"""Autoencoders trained with each mirror mode vs PCA-16 and the mean pose on the same held-out clips.

    python experiments/tgst_bandai/compare_mirror.py OUT.md RESULTS_DIR MODE[,MODE...] SEED[,SEED...] [PREFIX]

Reads RESULTS_DIR/diagnose_{PREFIX}{MODE}_s{SEED}.json (diagnose.py, PREFIX default ``mir_``) and writes a
markdown report: mean angle per joint (AE per mode averaged over seeds, baselines), the per-seed means, and
paired differences of the per-clip mean angles (clip = unit; mean +- standard error over clips, and the
number of clips where the first is lower), for every pair of modes and for each mode against PCA-16 (fitted
on the original training clips) and the mean pose; a run of another latent width also against the PCA of its
width (``pca_<mode>``).
"""
import itertools
import json
import pathlib
import sys

import numpy as np


def paired(a, b):
    d = np.asarray(a) - np.asarray(b)
    return f"{d.mean():+.2f} +- {d.std(ddof=1) / np.sqrt(len(d)):.2f} | {(d < 0).sum()}/{len(d)}"


def main(out, res, modes, seeds, prefix="mir_"):
    res = pathlib.Path(res)
    runs = {m: {s: json.loads((res / f"diagnose_{prefix}{m}_s{s}.json").read_text()) for s in seeds
                if (res / f"diagnose_{prefix}{m}_s{s}.json").is_file()} for m in modes}
    runs = {m: r for m, r in runs.items() if r}
    first = next(iter(next(iter(runs.values())).values()))
    clips, joints = first["clips"], list(first["angle_deg"]["autoencoder"]["per_joint"])
    rows, per_clip = {}, {}
    for m, by_seed in runs.items():
        for r in by_seed.values():
            assert r["clips"] == clips, "diagnose files of different clip sets"
        pj = np.mean([np.asarray(r["angle_deg"]["autoencoder"]["per_clip_joint"]) for r in by_seed.values()], 0)
        rows[f"AE {m} ({len(by_seed)} seed(s): {', '.join(str(s) for s in by_seed)})"] = pj.mean(0)
        per_clip[m] = pj.mean(1)
    for k, label in (("pca16", "PCA-16 (original clips)"), ("pca16_mix", "PCA-16 (original + mirrored clips)"),
                     ("mean_pose", "mean pose (original clips)")):
        pj = np.asarray(first["angle_deg"][k]["per_clip_joint"])
        rows[label] = pj.mean(0)
        per_clip[k] = pj.mean(1)
    for m, by_seed in runs.items():  # a run with another latent width has its own PCA (same width)
        r = next(iter(by_seed.values()))
        if r["angle_deg"]["pca16"]["per_clip"] != first["angle_deg"]["pca16"]["per_clip"]:
            pj = np.asarray(r["angle_deg"]["pca16"]["per_clip_joint"])
            rows[f"PCA of the latent width of {m} (original clips)"] = pj.mean(0)
            per_clip[f"pca_{m}"] = pj.mean(1)
    lines = [f"Held-out clips: {len(clips)}; mean geodesic angle (deg) per joint over frames, then clips.", "",
             "| model | " + " | ".join(joints) + " | mean |", "|---" * (len(joints) + 2) + "|"]
    for name, v in rows.items():
        lines.append(f"| {name} | " + " | ".join(f"{x:.1f}" for x in v) + f" | **{v.mean():.2f}** |")
    lines += ["", "Per seed (mean over clips and joints): " + "; ".join(
        f"{m}: " + ", ".join(f"s{s} {r['angle_deg']['autoencoder']['mean']:.2f}" for s, r in by_seed.items())
        for m, by_seed in runs.items()), "",
              "Paired differences of the per-clip mean angle (deg; AE per clip averaged over its seeds): "
              "mean +- standard error over clips | clips where the first is lower.", "",
              "| first - second | difference | first lower |", "|---|---|---|"]
    for a, b in itertools.combinations(list(runs), 2):
        lines.append(f"| AE {a} - AE {b} | " + paired(per_clip[a], per_clip[b]).replace(" | ", " | ") + " |")
    for a in runs:
        for b in ("pca16", "pca16_mix", "mean_pose", f"pca_{a}"):
            if b in per_clip:
                lines.append(f"| AE {a} - {b} | " + paired(per_clip[a], per_clip[b]) + " |")
    text = "\n".join(lines) + "\n"
    pathlib.Path(out).write_text(text)
    print(text)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3].split(","), [int(s) for s in sys.argv[4].split(",")],
         *(sys.argv[5:6] or []))
