"""Ranking within groups: rows sorted by (group, fitness desc, row asc) and the top n of each
group, shared by the elites of SwarmCoDe's reproduction, its partners' elite rows and the
baselines' fixed-group reproduction; and the elite count of a species of a given size."""

from __future__ import annotations

from typing import overload

import torch
import torch.nn.functional as F
from torch import Tensor

from ..sim.tensors import arange
from .config import SwarmCoDeConfig


@overload
def elite_count(species_size: Tensor, max_elite: int = ...) -> Tensor: ...
@overload
def elite_count(species_size: int, max_elite: int = ...) -> int: ...
def elite_count(
    species_size: Tensor | int, max_elite: int = SwarmCoDeConfig.max_elite
) -> Tensor | int:
    """[K] long (or int) species sizes -> [K] long (or int) N = max(1, min(max_elite,
    size // 5 + 1)); max_elite is the paper's E."""
    if isinstance(species_size, Tensor):
        if max_elite < 1:  # max(1, min(max_elite, .)) is 1
            return torch.ones_like(species_size)
        return (species_size // 5 + 1).clamp(1, max_elite)
    return max(1, min(max_elite, int(species_size) // 5 + 1))


def group_sizes(group: Tensor, n: int) -> Tensor:
    """group [P] long in 0..n-1 -> [n] long rows per group: `torch.bincount(group, minlength=n)`
    without its device sync (bincount reads the largest value on the host to size its output)."""
    return torch.zeros(n, dtype=torch.long, device=group.device).scatter_add_(
        0, group, torch.ones_like(group)
    )


def rank_within_groups(
    group: Tensor, fitness: Tensor, sizes: Tensor | None = None, first: Tensor | None = None
) -> tuple[Tensor, Tensor]:
    """group [P] long >= 0, fitness [P] -> (order [P], rank [P]).

    order: the rows sorted by (group asc, fitness desc, row asc) (stable sorts, so equal fitness
    keeps the lower row first; NaN sorts as torch.sort puts it); with `first` [P] bool, rows
    where it holds rank above the others of equal fitness, (group, first desc, fitness desc, row).
    rank[j]: the position of order[j] within its group (0: its best). `sizes` [G] (G > the
    largest group) are the rows per group, `torch.bincount(group)` when not given.
    """
    order = torch.sort(fitness, descending=True, stable=True).indices
    if first is not None:
        order = order[torch.sort((~first[order]).to(torch.uint8), stable=True).indices]
    by_group = torch.sort(group[order], stable=True)  # its values: the groups in that order
    order = order[by_group.indices]
    if sizes is None:
        sizes = torch.bincount(group)
    starts = sizes.cumsum(0) - sizes
    rank = arange(group.numel(), group.device) - starts[by_group.values]
    return order, rank


def top_per_group(
    order: Tensor, rank: Tensor, group: Tensor, n: Tensor, total: int | None = None
) -> Tensor:
    """`rank_within_groups`' (order, rank) of `group` [P], n [G] -> the rows of the best n[g] of
    every group g, by group, best first (every row's group must be < G). `total`: their number,
    where known on the host (no value is then read on the host here)."""
    keep = rank < n[group[order]]
    if total is None:
        return order[keep]
    return order[torch.sort((~keep).to(torch.uint8), stable=True).indices[:total]]


def top_table(
    order: Tensor, rank: Tensor, group: Tensor, n: Tensor, width: int | None = None
) -> Tensor:
    """`rank_within_groups`' (order, rank) of `group` [P], n [G] (G >= 1) -> [G, M] long: row g
    holds the rows of the best n[g] of group g, best first, -1 padded; M = `width` where given
    (no n may exceed it: no value is read on the host), else max(n). Rows of group G (no group)
    are left out."""
    k = n.numel()
    m = int(n.max()) if width is None else width
    dev = order.device
    g = group[order]
    keep = rank < F.pad(n, (0, 1))[g]  # group G keeps none
    flat = torch.full((k * m + 1,), -1, dtype=torch.long, device=dev)
    target = torch.where(keep, g * m + rank, k * m)
    flat.scatter_(0, target, torch.where(keep, order, -1))
    return flat[: k * m].view(k, m)
