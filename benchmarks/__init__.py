"""The benchmark suite moved into the package (:mod:`jaxgest.bench`); this folder keeps the stored results
(``results/``) and ``python -m benchmarks`` as an alias of ``jaxgest bench``."""
