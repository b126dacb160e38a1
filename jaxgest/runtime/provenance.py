"""Stamped results files: every result names the commit, the package version, the resolved config and the
command that produced it.

A results file is JSON of the form ``{"stamp": {...}, "results": {...}}``. :func:`stamp` builds the stamp,
:func:`write_results` writes it atomically, :func:`read_results` reads it back and refuses a file without a
complete stamp (one line naming the file). Experiment READMEs generate their tables from such files.

References: docs/design.md (results and provenance).
"""

from __future__ import annotations

import hashlib
import json
import os
import pathlib
import platform
import shlex
import subprocess
import sys

from jaxgest.runtime.errors import DataError
from jaxgest.runtime.io import write_json_atomic

STAMP_KEYS = ("commit", "dirty", "version", "config", "command")
#: where experiments and benchmarks keep their stamped results and the READMEs whose tables the driver rewrites from them
#: (git pathspec globs from the checkout's top): not code, so a rewritten results file or README table (by this
#: run or one beside it) does not make a stamp dirty
RESULTS_PATHS = ("experiments/*/out/**", "experiments/*/results/**", "experiments/*/README.md",
                 "benchmarks/results/**")


def _git(args, cwd) -> str | None:
    try:
        out = subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


#: the environment variables that set threads (XLA's flags, the BLAS pools): the same seed can train other
#: parameters under other threading (another reduction order), so a stamp records them
THREAD_ENV = ("XLA_FLAGS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``; ``platform.processor()`` elsewhere)."""
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return cpu


def _checkout_dir(path=None) -> pathlib.Path:
    """The folder to run git in for ``path`` (default: this package)."""
    where = pathlib.Path(path) if path is not None else pathlib.Path(__file__).resolve().parent
    return where if where.is_dir() else where.parent


#: git pathspec of the code: the whole checkout except :data:`RESULTS_PATHS`
_CODE = ("--", ":(top)", *(f":(top,glob,exclude){p}" for p in RESULTS_PATHS))


def _changed(where: pathlib.Path) -> list[str] | None:
    """The tracked code files that differ from the commit (one ``git status``); None outside a checkout."""
    status = _git(["status", "--porcelain", "--untracked-files=no", *_CODE], where)
    return None if status is None else [line.split(None, 1)[1] for line in status.splitlines() if line.strip()]


def _limited(paths: list[str], limit: int) -> list[str]:
    return paths[:limit] + ([f"... and {len(paths) - limit} more"] if len(paths) > limit else [])


def dirty_paths(path=None, limit: int = 50) -> list[str] | None:
    """The tracked files (not results, :data:`RESULTS_PATHS`) that differ from the commit, at most ``limit``
    (then a last entry ``"... and N more"``); None outside a checkout."""
    paths = _changed(_checkout_dir(path))
    return None if paths is None else _limited(paths, limit)


def commit_of(path=None) -> tuple[str | None, bool | None]:
    """(commit hash, working tree dirty?) of the git checkout holding ``path`` (default: this package).

    Dirty means a tracked file differs from the commit, other than the results files themselves and the
    experiment READMEs whose tables are generated from them (:data:`RESULTS_PATHS`): an evaluation that
    rewrites a committed results file or table, or runs beside one that does, is still the commit's code.
    ``(None, None)`` outside a checkout (an installed package): the stamp then says so instead of guessing.
    """
    where = _checkout_dir(path)
    head = _git(["rev-parse", "HEAD"], where)
    if head is None:
        return None, None
    return head, bool(_changed(where))


def process_command(argv=None, root=None) -> list[str]:
    """This process's command line as it can be typed again from ``root`` (default: the working directory):
    a Python script as ``python PATH``, a package's ``__main__.py`` as ``python -m PACKAGE``, and paths under
    ``root`` relative to it (an absolute path under a clone names that machine, not the experiment)."""
    argv = list(sys.argv if argv is None else argv)
    root = pathlib.Path(root if root is not None else pathlib.Path.cwd()).resolve()

    def rel(arg: str) -> str:
        try:
            return str(pathlib.Path(arg).resolve().relative_to(root)) if pathlib.Path(arg).is_absolute() else arg
        except ValueError:
            return arg

    head = pathlib.Path(argv[0]) if argv else pathlib.Path("python")
    if head.name == "__main__.py":
        first = ["python", "-m", ".".join(pathlib.Path(rel(str(head.parent))).parts)]
    elif head.suffix == ".py":
        first = ["python", rel(str(head))]
    else:
        first = [head.name]
    return first + [rel(a) for a in argv[1:]]


def diff_sha256(path=None) -> str | None:
    """SHA-256 of the uncommitted changes to tracked files (``git diff HEAD``, results excluded as in
    :func:`commit_of`): two dirty trees with the same commit and hash ran the same code. None outside a checkout."""
    diff = _git(["diff", "HEAD", *_CODE], _checkout_dir(path))
    return None if diff is None else hashlib.sha256(diff.encode()).hexdigest()


def code_stamp(command: str | list | None = None, repo=None) -> dict:
    """What ran: commit (and whether the tree had uncommitted changes: then which files, ``dirty_paths``, and
    their diff's hash, ``diff_sha256``), package version, the command (default: this process's argv), and the
    machine: CPU model, cores and the thread settings (:data:`THREAD_ENV`). Trainings write it into their
    workdir's config.json (``"code"``); :func:`stamp` holds it too."""
    from jaxgest._version import __version__
    import jax

    if command is None:
        command = process_command()
    if not isinstance(command, str):
        command = shlex.join(str(c) for c in command)
    where = _checkout_dir(repo)
    commit = _git(["rev-parse", "HEAD"], where)
    changed = _changed(where) if commit is not None else None  # one git status for dirty and its paths
    dirty = None if commit is None else bool(changed)
    return {
        "commit": commit,
        "dirty": dirty,
        **({"dirty_paths": _limited(changed, 50), "diff_sha256": diff_sha256(repo)} if dirty else {}),
        "version": __version__,
        "command": command,
        "python": platform.python_version(),
        "jax": jax.__version__,
        "machine": platform.machine(),
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "threads": {k: os.environ[k] for k in THREAD_ENV if k in os.environ},
    }


def training_code(workdir) -> dict | None:
    """The ``"code"`` stamp a training wrote into ``workdir/config.json`` (None for a workdir from before it,
    or none at all)."""
    try:
        code = json.loads((pathlib.Path(workdir) / "config.json").read_text()).get("code")
    except (OSError, ValueError, AttributeError):
        return None
    return code if isinstance(code, dict) else None


def stamp(config: dict, command: str | list | None = None, repo=None, workdir=None) -> dict:
    """The stamp of a result: :func:`code_stamp` and the resolved config (as given: a JSON-able dict); with
    ``workdir`` (the trained model evaluated) also ``"training"``, the code stamp its training wrote."""
    out = code_stamp(command, repo)
    out["config"] = json.loads(json.dumps(config, default=str))
    if workdir is not None:
        out["training"] = training_code(workdir)
    return out


def write_results(path, results: dict, config: dict, command=None, workdir=None) -> pathlib.Path:
    """Write ``{"stamp": stamp(config, command, workdir=workdir), "results": results}`` to ``path`` atomically."""
    return write_json_atomic(path, {"stamp": stamp(config, command, repo=pathlib.Path(path).resolve().parent,
                                                   workdir=workdir),
                                    "results": results})


def read_results(path) -> dict:
    """A results file's ``{"stamp", "results"}``; :class:`DataError` (one line) when it is not one."""
    path = pathlib.Path(path)
    try:
        obj = json.loads(path.read_text())
    except FileNotFoundError:
        raise DataError(f"{path}: no such results file") from None
    except (OSError, ValueError) as e:
        raise DataError(f"{path}: not a readable JSON results file ({e})") from None
    if not isinstance(obj, dict) or "stamp" not in obj or "results" not in obj:
        raise DataError(f"{path}: not a stamped results file (needs 'stamp' and 'results')")
    missing = [k for k in STAMP_KEYS if k not in obj["stamp"]]
    if missing:
        raise DataError(f"{path}: stamp lacks {', '.join(missing)}")
    return obj
