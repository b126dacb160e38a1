"""What both peers share: torch threads and numpy -> torch float32."""

from __future__ import annotations

import numpy as np
import torch


def set_threads(n: int) -> int:
    """Intra-op threads of torch (the XLA CPU client uses every core of the process): returns n."""
    torch.set_num_threads(int(n))
    return torch.get_num_threads()


def tensor(a) -> torch.Tensor:
    """A float32 torch copy of an array (numpy or JAX)."""
    return torch.from_numpy(np.array(a, dtype=np.float32, copy=True))
