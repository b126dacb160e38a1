"""The runtime layer: the training loop, checkpoints and their faults, parallelism, atomic I/O, the workdir
format, errors and results provenance. Below ``tgst``/``zeggs`` (never imports them); this ``__init__`` imports
nothing, so ``from jaxgest.runtime.errors import ...`` stays cheap for the bottom layers."""
