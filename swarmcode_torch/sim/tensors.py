"""Small tensor helpers shared by the simulator and the algorithm."""

from __future__ import annotations

import functools
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


def arange(n: int, device: torch.device | str | None = None) -> torch.Tensor:
    """[n] long 0..n-1 on `device`: one tensor per (n, device), built once and shared, so never
    to be written to (built afresh while torch.compile traces, which would bypass the cache)."""
    dev = torch.device("cpu" if device is None else device)
    if torch.compiler.is_compiling():
        return torch.arange(n, device=dev)
    return _arange(n, dev)


@functools.lru_cache(maxsize=256)
def _arange(n: int, device: torch.device) -> torch.Tensor:
    return torch.arange(n, device=device)
