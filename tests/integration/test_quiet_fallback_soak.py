"""A fall-back past an unreadable checkpoint prints its one warning line and nothing else, every time.

orbax runs each restore in a fresh asyncio loop; when one array read fails, the reads of the other arrays used
to stay pending in the closed loop and, whenever the garbage collector finalised them, print screens of
"Exception ignored in: <coroutine object _read_array_index_and_device_put ...>" / "Task exception was never
retrieved" tracebacks -- in some runs only. :func:`jaxgest.runtime.orbax_noise.settled_event_loops` lets those reads
end before the loop closes. Here one fresh process restores the damaged workdir many times with a garbage
collection after each (no process-wide filter installed: not through ``jaxgest.cli.main``), and its stderr must
be exactly one line per restore. The real command in a fresh process is
``test_corrupt_checkpoint_in_a_real_process_is_one_clean_line`` (tests/test_faults_checkpoints.py).
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from faults_testing import copy, garbage_meta, missing_state, subprocess_env, truncate_data

LOOP = r"""
import gc, sys
from jaxgest.runtime.checkpoint import strict_checkpoints
from jaxgest.runtime.errors import JaxgestError
from jaxgest.tgst import workdir as W

for arg in sys.argv[1:]:
    work, n, strict = arg.split(",")
    cfg = W.read_config(work)
    for _ in range(int(n)):
        try:
            with strict_checkpoints(strict == "1"):
                W.restore_params(work, cfg.model)
        except JaxgestError as e:
            print(f"jaxgest: {e}", file=sys.stderr, flush=True)
        gc.collect()
"""


@pytest.mark.slow
def test_fallback_is_one_line_every_time(tiny, tmp_path):
    cases = []  # (workdir, restores, strict, the line each restore must print)
    for name, damage, n, reason in (("truncated", truncate_data, 30, "a data file is truncated or corrupted"),
                                    ("missing", missing_state, 2, "a file is missing"),
                                    ("garbage", garbage_meta, 2, "its metadata is not valid JSON")):
        work = copy(tiny, "tgst", tmp_path / name)
        damage(work / "checkpoints" / "transformer" / "4")
        cases.append((work, n, False, f"transformer checkpoint at step 4 is unreadable ({reason}); using step 2 "
                                      "instead (nothing was changed; --strict refuses)"))
    cases.append((cases[0][0], 2, True, "transformer checkpoint at step 4 is unreadable (a data file is truncated "
                                        "or corrupted); --strict: not falling back to step 2"))
    r = subprocess.run([sys.executable, "-c", LOOP, *(f"{w},{n},{int(s)}" for w, n, s, _ in cases)],
                       env=subprocess_env(), capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    lines = r.stderr.splitlines()
    expected = [(w, line) for w, n, _, line in cases for _ in range(n)]
    assert len(lines) == len(expected), r.stderr[-3000:]
    for got, (work, line) in zip(lines, expected):
        assert got.startswith("jaxgest: ") and f"{work}: {line}" in got, got
