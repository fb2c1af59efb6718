"""Small tensor helpers shared by the simulator and the algorithm."""

from __future__ import annotations

import torch


def cast(
    t: torch.Tensor, dtype: torch.dtype | None = None, device: torch.device | str | None = None
) -> torch.Tensor:
    """t in `dtype` on `device` (None: as it is): t itself where it already is, without even a
    no-op `.to` (each call of an op is a dispatch, and a generation makes many)."""
    if (dtype is None or t.dtype == dtype) and (device is None or t.device == torch.device(device)):
        return t
    return t.to(device=device, dtype=dtype)
