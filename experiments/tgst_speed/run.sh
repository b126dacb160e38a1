#!/usr/bin/env bash
# TGST transfer speed levers at batch 8 (README.md): run from the repository root on an idle machine.
set -euo pipefail
cd "$(dirname "$0")"
PY=${PYTHON:-python}
(cd ../.. && $PY -m benchmarks.tgst_profile 8)
$PY two_devices.py 8
$PY peer_two_devices.py 8
NO_TORCH=1 $PY peer_two_devices.py 8
$PY compile_options.py 8 '{"vw512": {"xla_cpu_prefer_vector_width": 512}, "conc": {"xla_cpu_enable_concurrency_optimized_scheduler": true}, "fastmath": {"xla_cpu_enable_fast_math": true}, "nofusemit": {"xla_cpu_use_fusion_emitters": false}}'
$PY bf16.py 8
