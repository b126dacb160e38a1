"""The table of "Half of the style comes from the initial pose": the `e64_8k` seeds against the
`initial_pose_shuffle=0.5` seeds, from the JSONs each run's commands wrote into ``out/``.

    python experiments/zeggs_synthetic/initial_pose_table.py out e64_8k,e64_8k_s1,e64_8k_s2 ips50_8k,ips50_8k_s1,ips50_8k_s2

Per run: crossed generation t (``static_style_<run>.json``), pooled style probe and its differences to the
raw statistics and the random init, pooled content probe (``eval_pooled_<run>.json``, or the run's
``pooled_<run>`` entry of ``window_runs.json``), the held-out leakage contrast on one dataset and pooled over 8
(``eval_<run>_heldout.json``, ``leakage_pooled_<run>.json``), Fréchet x floor and BeatAlign - shuffled on
training / held-out scripts (``eval_<run>[_heldout].json`` or ``window_runs.json``).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path


def load(out: Path, name: str):
    f = out / f"{name}.json"
    if f.is_file():
        return json.loads(f.read_text())
    runs = json.loads((out / "window_runs.json").read_text())
    key = name[len("eval_"):] if name.startswith("eval_") else None
    if name.startswith("eval_pooled_"):
        key = "pooled_" + name[len("eval_pooled_"):]
    return runs[key]


def row(out: Path, run: str) -> list[str]:
    st = load(out, f"static_style_{run}")["crossed"]
    pp = load(out, f"eval_pooled_{run}")["probe_pooled"]
    lk = load(out, f"leakage_pooled_{run}")["pooled"]["other_style - same_style_other_content"]
    ev, eh = load(out, f"eval_{run}"), load(out, f"eval_{run}_heldout")

    def fr(d):
        f = d["frechet_distance"]
        return f["generated_vs_real"] / f["real_train_vs_real_test"]

    def beat(d):
        b = d["beat_alignment"]["generated_vs_control"]
        return f"{b['mean']:+.3f} +- {b['standard_error']:.3f}"

    s = pp["style"]
    raw, rnd = s["trained_minus"]["raw_statistics"], s["trained_minus"]["random_init"]
    z1 = eh["leakage"]["contrasts"]["other_style - same_style_other_content"]["z"]
    return [run, f"{st['static']['mean']:.2f} / {st['dynamic']['mean']:.2f}",
            f"{s['trained']['accuracy']:.3f}", f"{raw['mean']:+.3f} +- {raw['standard_error']:.3f}",
            f"{rnd['mean']:+.3f}", f"{pp['content']['trained']['accuracy']:.3f}",
            f"{z1:.1f} / {lk['z']:.1f}", f"{fr(ev):.2f} / {fr(eh):.2f}", f"{beat(ev)} / {beat(eh)}"]


def main() -> int:
    out = Path(sys.argv[1])
    head = ["run", "crossed t static / dynamic", "pooled style probe", "- raw statistics (+- SE)", "- random init",
            "pooled content probe", "leak (d)-(c) z held-out: one set / pooled 8", "Fréchet x floor train / held-out",
            "BeatAlign - shuffled train / held-out"]
    print("| " + " | ".join(head) + " |")
    print("|---|" + "---:|" * (len(head) - 1))
    for group in sys.argv[2:]:
        for run in group.split(","):
            print("| " + " | ".join(row(out, run)) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
