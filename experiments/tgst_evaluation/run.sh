#!/usr/bin/env bash
# TGST evaluation protocol check on Bandai-Namco-1 (README.md beside this file):
#
#   bash experiments/tgst_evaluation/run.sh            # from anywhere; SHARED=/path/to/shared to override
#
# 1. a tiny-preset model (200 + 200 steps) in out/tiny;
# 2. the full intra evaluation (all pairs, authors' protocol, default buckets), with wall and CPU time;
# 3. a 40-pair subset with exact shapes (--bucket 1) and with the default buckets; paired comparison;
# 4. Table 1 (metric validity) under both protocols.
# Every run starts from an empty compilation cache (out/xla-*), so the timings include compilation.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
shared="${SHARED:-$repo/../shared}"
data="$shared/data/bandai-namco-1/data"
out="$here/out"
mkdir -p "$out"
cd "$repo"

[ -f "$out/tiny/config.json" ] || jaxgest tgst train --data "$data" --workdir "$out/tiny" --preset tiny
run() {  # name, extra args
  local name=$1; shift
  rm -rf "$out/xla-$name"
  JAX_COMPILATION_CACHE_DIR="$out/xla-$name" /usr/bin/env time -p \
    jaxgest tgst evaluate --workdir "$out/tiny" --data "$data" --json "$out/$name.json" "$@" | tee "$out/$name.md"
}
run intra --max-pairs 0
run exact40 --max-pairs 40 --bucket 1
run bucket40 --max-pairs 40
python "$here/compare_buckets.py" "$out/exact40.json" "$out/bucket40.json" | tee "$out/compare40.md"
python - "$data" <<'PY' | tee "$out/validity.md"
import sys, time
from jaxgest.tgst.evaluate import metric_validity, validity_table
for protocol in ("authors", "world"):
    t, c = time.perf_counter(), time.process_time()
    v = metric_validity(sys.argv[1], pairs="inter", progress=False, protocol=protocol)
    print(validity_table(v))
    print(f"{v['num_evaluated']} of {v['num_pairs']} pairs; {time.perf_counter() - t:.0f} s wall, "
          f"{time.process_time() - c:.0f} s CPU\n")
PY
