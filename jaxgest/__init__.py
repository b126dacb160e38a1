"""jaxgest: JAX/Flax gesture animation.

Two published systems, reimplemented pure-functionally:

* ``jaxgest.tgst``  -- tokenized gesture style transfer (Kuriyama et al. 2022).
* ``jaxgest.zeggs`` -- ZeroEGGS speech-driven gesture generation (Ghorbani et al. 2023).

Motion data lives in ``jaxgest.motion`` (BVH, rotations, skeletons, kinematics, synthetic data).
"""

__version__ = "0.1.0"
