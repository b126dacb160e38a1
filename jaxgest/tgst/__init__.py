"""Tokenized gesture style transfer (Kuriyama et al. 2022).

    model = jaxgest.tgst.load("runs/tgst")            # a trained workdir (jaxgest tgst train / train())
    out = model.transfer("content.bvh", "style.bvh", method="soft")   # paths or Motions -> Motion

:func:`train` trains (or resumes) both stages into a workdir; :func:`count_params` counts a preset's
parameters. Modules: ``config`` (presets), ``model``/``autoencoder``/``transformer``/``swap`` (the
networks and equations), ``train``, ``api`` (loading, Motion-level transfer), ``evaluate``, ``protocol``.
"""

from jaxgest.tgst.api import METHODS, TGSTModel, count_params, load, transfer
from jaxgest.tgst.trainer import train

__all__ = ["METHODS", "TGSTModel", "count_params", "load", "train", "transfer"]
