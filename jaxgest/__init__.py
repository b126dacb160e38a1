"""jaxgest: JAX/Flax gesture animation.

Two published systems, reimplemented pure-functionally:

* ``jaxgest.tgst``  -- tokenized gesture style transfer (Kuriyama et al. 2022).
* ``jaxgest.zeggs`` -- ZeroEGGS speech-driven gesture generation (Ghorbani et al. 2023).

    import jaxgest as jg
    clip = jg.load_bvh("content.bvh")                                   # a jg.Motion
    styled = jg.tgst.load("runs/tgst").transfer(clip, "style.bvh")      # paths or Motions
    gestures = jg.zeggs.load("runs/zeggs").generate("speech.wav", "style.bvh", seed=0)
    jg.save_bvh(styled, "styled.bvh")

Motion data lives in ``jaxgest.motion`` (BVH, rotations, skeletons, kinematics, synthetic data), metrics in
``jaxgest.metrics``, the infrastructure (training loop, checkpoints, I/O) in ``jaxgest.runtime``.
"""

from jaxgest import tgst, zeggs
from jaxgest._version import __version__
from jaxgest.motion.bvh import load as load_bvh
from jaxgest.motion.bvh import save as save_bvh
from jaxgest.motion.skeleton import Motion, Skeleton

__all__ = ["Motion", "Skeleton", "__version__", "load_bvh", "save_bvh", "tgst", "zeggs"]
