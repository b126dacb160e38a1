#!/usr/bin/env bash
# This experiment from scratch, one step at a time or all of it (logs in out/logs). Its runs are in runs/
# (not configs/: that folder name is for configs of the experiments driver, python -m experiments):
#   bash experiments/tgst_bandai2/run.sh [all|train|evaluate|tables] [runs/NAME.toml ...]
# all (default): train every config given (default: every runs/*.toml, one at a time), evaluate them,
# Table 1 (data only), then rewrite the README tables (about 1 h 10 min on 2 cores; needs ../shared/data/bandai-namco-2).
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
STEP="${1:-all}"; shift || true
CONFIGS=()
for c in "$@"; do CONFIGS+=("$(realpath "$c")"); done
[ ${#CONFIGS[@]} -eq 0 ] && CONFIGS=("$HERE"/runs/*.toml)
cd "$HERE/../.."
export PYTHONPATH="$PWD" JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS=0.2 MPLBACKEND=Agg
PY="${PYTHON:-python}"
mkdir -p "$HERE/out/logs" "$HERE/results"

each() {  # each SCRIPT LOG-PREFIX: run SCRIPT on every config, one after another
  for c in "${CONFIGS[@]}"; do
    n="$(basename "$c" .toml)"
    echo "$(date -u +%T) $1 $n"
    "$PY" "$HERE/$1.py" "$c" > "$HERE/out/logs/$2$n.log" 2>&1
    echo "$(date -u +%T) done $n ($(tail -1 "$HERE/out/logs/$2$n.log" | tail -c 200))"
  done
}

case "$STEP" in
  train) each train "" ;;
  evaluate) each evaluate eval_ ;;
  tables) "$PY" "$HERE/tables.py" ;;
  all) each train ""; each evaluate eval_; "$PY" "$HERE/evaluate.py" --table1; "$PY" "$HERE/tables.py" ;;
  *) echo "run.sh: unknown step '$STEP' (all, train, evaluate, tables)" >&2; exit 2 ;;
esac
