"""jaxgest per-pose CPU cost benchmarks (docs/design.md §8): ``jaxgest bench`` or ``python -m jaxgest.bench``.

Installed with the package. ``harness`` times and checks, ``report`` prints tables and plots, ``cases/``
holds the registered workloads, ``torch_peers/`` the PyTorch ports the peer cases time (needs the
``[bench]`` extra; torch is imported only by those cases). Stored results stay in the clone's
``benchmarks/results/``.
"""
