"""The ZeroEGGS authors' released models, run by jaxgest (``jaxgest zeggs import-official``).

* :mod:`~jaxgest.zeggs.official.features` -- their pose features (joint-local state, root, gaze);
* :mod:`~jaxgest.zeggs.official.network` -- their speech encoder, style encoder and decoder as pure JAX
  functions of their own parameter names;
* :mod:`~jaxgest.zeggs.official.release` -- reading a clone of their repository, writing / reading a workdir;
* :mod:`~jaxgest.zeggs.official.model` -- :class:`OfficialZeggs`, generation as their ``generate_gesture``.

References: Ghorbani et al. 2023; the authors' repository ubisoft/ubisoft-laforge-ZeroEGGS (CC BY-NC-ND 4.0:
no weights or adapted files of theirs are part of jaxgest).
"""

from jaxgest.zeggs.official.model import OfficialZeggs, load
from jaxgest.zeggs.official.release import import_release, is_official

__all__ = ["OfficialZeggs", "import_release", "is_official", "load"]
