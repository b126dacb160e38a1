#!/usr/bin/env bash
# Every table of this experiment from scratch: train the 6 runs (+ bn1plus), evaluate them, Table 1, README tables.
#   bash experiments/tgst_bandai2/run.sh        (about 1 h on 2 cores; needs ../shared/data/bandai-namco-2)
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
PY="${PYTHON:-python}"
bash "$HERE/train_all.sh" "$HERE"/configs/*.json
bash "$HERE/eval_all.sh" "$HERE"/configs/*.json
"$PY" "$HERE/evaluate.py" --table1
"$PY" "$HERE/tables.py"
