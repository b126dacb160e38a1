"""Public TGST entry points (SPEC.md §7).

``count_params(preset)`` is here; ``transfer(content: Motion, style: Motion, *, workdir, method)`` (the
Motion-level API the CLI calls) is added by the lead on top of :func:`jaxgest.tgst.model.transfer_arrays`.
"""

from __future__ import annotations

import jax

from jaxgest.tgst.config import get_config
from jaxgest.tgst.model import init_params


def count_params(preset: str = "paper") -> dict[str, int]:
    """Parameter counts ``{"autoencoder": int, "transformer": int}`` of a fresh model of ``preset``.

    Computed with ``jax.eval_shape`` (no weights are materialised). Paper: 23,743 and 50,240.
    """
    cfg = get_config(preset)
    shapes = jax.eval_shape(lambda k: init_params(cfg, k), jax.random.PRNGKey(0))
    return {name: int(sum(x.size for x in jax.tree_util.tree_leaves(tree))) for name, tree in shapes.items()}
