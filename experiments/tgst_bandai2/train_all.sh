#!/usr/bin/env bash
# Train every run of configs/ given (default: all), one after another (never two at once), logs in out/logs.
#   bash experiments/tgst_bandai2/train_all.sh [configs/full_s0.json ...]
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
CONFIGS=()
for c in "$@"; do CONFIGS+=("$(realpath "$c")"); done
cd "$HERE/../.."
export PYTHONPATH="$PWD" JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS=0.2 MPLBACKEND=Agg
PY="${PYTHON:-python}"
mkdir -p "$HERE/out/logs"
[ ${#CONFIGS[@]} -eq 0 ] && CONFIGS=("$HERE"/configs/full_s0.json "$HERE"/configs/full_s1.json "$HERE"/configs/full_s2.json \
                                     "$HERE"/configs/zeroshot_s0.json "$HERE"/configs/zeroshot_s1.json "$HERE"/configs/zeroshot_s2.json)
for c in "${CONFIGS[@]}"; do
  n="$(basename "$c" .json)"
  echo "$(date -u +%T) start $n"
  /usr/bin/time -f "%e s wall" "$PY" "$HERE/train.py" "$c" > "$HERE/out/logs/$n.log" 2>&1
  echo "$(date -u +%T) done $n ($(tail -1 "$HERE/out/logs/$n.log"))"
done
