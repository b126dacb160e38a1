"""ZeroEGGS: zero-shot example-based gesture generation from speech (Ghorbani et al. 2023).

    model = jaxgest.zeggs.load("runs/zeggs")          # a trained workdir (jaxgest zeggs train / train())
    out = model.generate("speech.wav", ["calm.bvh", "happy.bvh"], weights=[0.5, 0.5], seed=0)

``audio``: a path or ``(samples, sample_rate)``; styles: Motions or BVH paths. :func:`train` trains (or
resumes) into a workdir; :func:`count_params` counts a preset's parameters. Modules: ``config`` (presets),
``model`` and its parts, ``train``, ``inference`` (the loaded model), ``api``, ``evaluate``, ``pca``.
"""

from jaxgest.zeggs.api import TrainedZeggs, count_params, generate, load
from jaxgest.zeggs.trainer import train

__all__ = ["TrainedZeggs", "count_params", "generate", "load", "train"]
