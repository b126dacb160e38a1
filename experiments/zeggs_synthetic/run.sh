#!/usr/bin/env bash
# ZeroEGGS on the built-in synthetic data (+ a one-clip overfit on the real ZEGGS sample).
# Usage (from anywhere): PYTHON=/work/venv/bin/python nice -n 5 experiments/zeggs_synthetic/run.sh
# Environment: PYTHON (default python), STEPS (synthetic training steps, default 8000), OVERFIT_STEPS
# (default 1500), PROBE_SEEDS (datasets of the pooled probe, default 20), ZEGGS_DIR (default ../shared/data/speech-gesture/zeggs relative to the repo).
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/../.." && pwd)"
cd "$REPO"
PY="${PYTHON:-python}"
J=("$PY" -m jaxgest.cli)
OUT="${OUT:-experiments/zeggs_synthetic/out}"
STEPS="${STEPS:-8000}"
OVERFIT_STEPS="${OVERFIT_STEPS:-1500}"
PROBE_SEEDS="${PROBE_SEEDS:-20}"
ZEGGS_DIR="${ZEGGS_DIR:-$REPO/../shared/data/speech-gesture/zeggs}"
SEED=0
mkdir -p "$OUT"
declare -A WALL
t() { date +%s; }

# The `small` preset: a mid-size model between `tiny` and the paper (~25.5 M params): GRU 128, D_S 16, D_e 16,
# style windows 64-128 frames apart from the 64-frame target (style_sampling=disjoint), XLA's default optimisation.
MID=(--preset small)
EXTRA=(${TRAIN_OVERRIDES:-})  # e.g. TRAIN_OVERRIDES="--override style_sampling=overlap" for the paper's sampling

# 1. data: 6 contents x 7 styles, 10 s each, 60 fps, 21 joints, speech-like WAV
s=$(t); "${J[@]}" synth --out "$OUT/data" --seed $SEED > /dev/null; WALL[synth]=$(( $(t) - s ))

# 2. train (resumes if $OUT/work has a checkpoint)
s=$(t); "${J[@]}" zeggs train --data "$OUT/data" --workdir "$OUT/work" --steps "$STEPS" --seed $SEED \
    "${MID[@]}" "${EXTRA[@]}" | tee -a "$OUT/train.log"; WALL[train]=$(( $(t) - s ))

# 3. evaluation: probes with controls, leakage report, BeatAlign vs shuffled onsets, Fréchet distance
s=$(t); "${J[@]}" zeggs evaluate --workdir "$OUT/work" --data "$OUT/data" --json "$OUT/eval.json" --seed $SEED \
    | tee "$OUT/eval.md"; WALL[evaluate]=$(( $(t) - s ))

# 3b. the same evaluation on held-out scripts: new speech and stroke timings (synth --seed 1) the model never saw
s=$(t); "${J[@]}" synth --out "$OUT/data_heldout" --seed 1 > /dev/null
"${J[@]}" zeggs evaluate --workdir "$OUT/work" --data "$OUT/data_heldout" --json "$OUT/eval_heldout.json" --seed $SEED \
    | tee "$OUT/eval_heldout.md"; WALL[evaluate_heldout]=$(( $(t) - s ))

# 3c. the probes on PROBE_SEEDS more synthetic datasets pooled (synth seeds 1..N: the same contents and styles, new
#     scripts and performances; leave-one-content-out over the pooled clips; CIs over clips and over datasets)
s=$(t); probe_dirs=()
for k in $(seq 1 "$PROBE_SEEDS"); do
  [ -f "$OUT/probe_data/seed$k/manifest.csv" ] || "${J[@]}" synth --out "$OUT/probe_data/seed$k" --seed "$k" > /dev/null
  probe_dirs+=("$OUT/probe_data/seed$k")
done
"${J[@]}" zeggs evaluate --workdir "$OUT/work" --data "$OUT/data" --json "$OUT/eval_pooled.json" --seed $SEED \
    --no-generation --probe-data "${probe_dirs[@]}" | tee "$OUT/eval_pooled.md"; WALL[evaluate_pooled]=$(( $(t) - s ))

# 3d. diagnostics: probe feature variants against the raw statistics (same pooled folds); Fréchet distance split
"$PY" experiments/zeggs_synthetic/probe_diagnostics.py --workdir "$OUT/work" --data "${probe_dirs[@]}" \
    --json "$OUT/probe_diagnostics.json" | tee "$OUT/probe_diagnostics.md"
"$PY" experiments/zeggs_synthetic/frechet_diagnostic.py --workdir "$OUT/work" --data "$OUT/data" \
    --json "$OUT/frechet_diagnostic.json" --seed $SEED | tee "$OUT/frechet_diagnostic.md"
"$PY" experiments/zeggs_synthetic/damping_diagnostic.py --workdir "$OUT/work" --data "$OUT/data" \
    --json "$OUT/damping_diagnostic.json" --seed $SEED --parts loss,decay,predictability | tee "$OUT/damping_diagnostic.md"

# 4. blend sweep between two styles (style examples of another content than the speech: zero-shot)
s=$(t)
AUDIO="$OUT/data/greeting_neutral_0.wav"
A="$OUT/data/apology_energetic_0.bvh"; B="$OUT/data/apology_sad_0.bvh"
files=(); titles=()
for w in "1,0" "0.75,0.25" "0.5,0.5" "0.25,0.75" "0,1"; do
  f="$OUT/blend_${w/,/_}.bvh"
  "${J[@]}" zeggs generate --workdir "$OUT/work" --audio "$AUDIO" --style "$A" --style "$B" --weights "$w" \
      --seed $SEED --out "$f" > /dev/null
  files+=("$f"); titles+=("energetic/sad ${w/,//}")
done
"${J[@]}" render "${files[@]}" --out "$OUT/blend_sweep.gif" --titles "$(IFS=,; echo "${titles[*]}")" \
    --max-seconds 6 --fps 12 > /dev/null

# 5. PCA of style embeddings, edit along component 0 (-2, 0, +2 std), neutral style example
"${J[@]}" zeggs pca --workdir "$OUT/work" --data "$OUT/data" | tee "$OUT/pca.log"
files=(); titles=()
for d in -2 0 2; do
  f="$OUT/pca0_${d}.bvh"
  "${J[@]}" zeggs generate --workdir "$OUT/work" --audio "$AUDIO" --style "$OUT/data/apology_neutral_0.bvh" \
      --pca-edit "0=$d" --seed $SEED --out "$f" > /dev/null
  files+=("$f"); titles+=("PC0 ${d} std")
done
"${J[@]}" render "${files[@]}" --out "$OUT/pca_edit.gif" --titles "$(IFS=,; echo "${titles[*]}")" \
    --max-seconds 6 --fps 12 > /dev/null
WALL[blend_pca]=$(( $(t) - s ))

# 5b. numbers for the blend / PCA outputs (hand speed and height)
"$PY" experiments/zeggs_synthetic/extra_measures.py --workdir "$OUT/work" --data "$OUT/data" --out-dir "$OUT" \
    --json "$OUT/extra.json" > /dev/null

# 6. overfit on the one real ZEGGS clip (68 s, 75 joints, 30 fps, 16 kHz), then sanity measures
if [ -f "$ZEGGS_DIR/067_Speech_2_x_1_0.bvh" ]; then
  s=$(t)
  "${J[@]}" zeggs train --data "$ZEGGS_DIR" --workdir "$OUT/zeggs_overfit" --steps "$OVERFIT_STEPS" \
      --seed $SEED "${MID[@]}" "${EXTRA[@]}" --override batch_size=8 | tee -a "$OUT/overfit_train.log"
  "$PY" experiments/zeggs_synthetic/overfit_check.py --workdir "$OUT/zeggs_overfit" --data "$ZEGGS_DIR" \
      --json "$OUT/overfit.json" --out-bvh "$OUT/overfit_generated.bvh"
  "${J[@]}" render "$ZEGGS_DIR/067_Speech_2_x_1_0.bvh" "$OUT/overfit_generated.bvh" --out "$OUT/overfit_real.gif" \
      --titles "captured,generated (same audio)" --max-seconds 8 --fps 10 > /dev/null
  WALL[overfit]=$(( $(t) - s ))
else
  echo "no ZEGGS sample at $ZEGGS_DIR: skipping the overfit run" >&2
fi

# 7. one small summary (committed)
walls=""; for k in "${!WALL[@]}"; do walls+="\"$k\": ${WALL[$k]},"; done
"$PY" - "$OUT" "{${walls%,}}" "$STEPS" "$OVERFIT_STEPS" <<'PY'
import json, pathlib, sys
out, walls, steps, osteps = pathlib.Path(sys.argv[1]), json.loads(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
cfg = json.loads((out / "work" / "config.json").read_text())
lines = [json.loads(x) for x in (out / "work" / "metrics.jsonl").read_text().splitlines()]
last = [r for r in lines if r["step"] <= steps][-1]  # a run stopped after its last checkpoint logs beyond it
import re
def train_wall(log):  # training seconds summed over the invocations that trained (train logs are appended)
    p = out / log
    rows = re.findall(r"trained (\d+) steps \(resumed from (\d+)\).* in ([\d.]+) s", p.read_text()) if p.is_file() else []
    return round(sum(float(w) for n, s0, w in rows if int(s0) < int(n)), 1)
res = {"seed": 0, "steps": steps, "overfit_steps": osteps, "wall_s_this_invocation": walls,
       "training_wall_s": {"synthetic": train_wall("train.log"), "overfit": train_wall("overfit_train.log")},
       "preset": cfg["preset"],
       "config": {k: {**cfg["config"]["model"], **cfg["config"]["train"]}[k] for k in (
                  "gru_hidden", "init_hidden", "speech_channels", "speech_kernels", "speech_embedding",
                  "style_hidden", "style_embedding", "input_norm", "loudness", "batch_size", "window", "fps",
                  "style_window_min", "style_window_max", "style_sampling", "kl_center", "kl_growth", "kl_cap")},
       "final_train_metrics": {k: last[k] for k in ("step", "loss", "recon", "kl", "steps_per_s")},
       "first_logged_train_metrics": {k: lines[0][k] for k in ("step", "loss", "recon", "kl")},
       "evaluate": json.loads((out / "eval.json").read_text()),
       "evaluate_heldout_scripts": json.loads((out / "eval_heldout.json").read_text()),
       "evaluate_pooled_probe": json.loads((out / "eval_pooled.json").read_text())["probe_pooled"],
       "probe_diagnostics": json.loads((out / "probe_diagnostics.json").read_text()),
       "frechet_diagnostic": json.loads((out / "frechet_diagnostic.json").read_text())}
res["controls_and_outputs"] = json.loads((out / "extra.json").read_text())
if (out / "overfit.json").is_file():
    res["overfit_real_zeggs"] = json.loads((out / "overfit.json").read_text())
(out / "results.json").write_text(json.dumps(res, indent=2) + "\n")
print(json.dumps(res, indent=2))
PY
ls -la "$OUT"/*.gif
