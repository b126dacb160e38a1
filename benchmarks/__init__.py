"""jaxgest per-pose CPU cost benchmarks (SPEC §8): ``python -m benchmarks`` or ``jaxgest bench``.

Not installed with the package: run from a clone (the repository root must be importable). ``harness``
times and checks, ``report`` prints tables and plots, ``cases/`` holds the registered workloads.
"""
