"""Small tensor helpers shared by the simulator and the algorithm."""

from __future__ import annotations

from typing import Any

import torch


def cast(
    t: Any, dtype: torch.dtype | None = None, device: torch.device | str | None = None
) -> torch.Tensor:
    """t in `dtype` on `device` (None: as it is): t itself where it already is, without even a
    no-op `.to` (each call of an op is a dispatch, and a generation makes many); t may be
    anything `torch.as_tensor` takes."""
    if not isinstance(t, torch.Tensor):
        return torch.as_tensor(t, dtype=dtype, device=device)
    if (dtype is None or t.dtype == dtype) and (device is None or t.device == torch.device(device)):
        return t
    return t.to(device=device, dtype=dtype)
