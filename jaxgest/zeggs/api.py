"""ZeroEGGS user-facing API (SPEC §7). For now: parameter counts of the presets.

References: Ghorbani et al. 2023, Table 2 (about 25 M parameters).
"""

from __future__ import annotations

import jax
import numpy as np

from jaxgest.zeggs.config import ZeggsConfig, get_config
from jaxgest.zeggs.steps import init_params


def count_params(preset: str | ZeggsConfig = "paper") -> dict[str, int]:
    """Parameters of a freshly initialised model: ``{"speech_encoder", "style_encoder", "generator"}``.

    Shapes only (``jax.eval_shape``): nothing is allocated. The paper preset assumes the paper's 75-joint
    rig, pose vector 15 * 75 + 6 = 1131 channels.
    """
    cfg = preset if isinstance(preset, ZeggsConfig) else get_config(preset)
    shapes = jax.eval_shape(lambda k: init_params(cfg, k), jax.random.PRNGKey(0))
    return {name: int(sum(np.prod(x.shape) for x in jax.tree_util.tree_leaves(shapes[name])))
            for name in ("speech_encoder", "style_encoder", "generator")}
