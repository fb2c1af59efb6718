"""A sorted cell list (broad phase) built with torch ops on the robots' device, for the pair
phases of large swarms (N >= `WorldParams.broad_phase_min_robots`).

Robots are binned into square cells of side `cell_size` exactly as `contacts._cells` bins them
(so the same robots share a cell); `order` lists each environment's robot rows sorted by cell
(stable: ascending rows within a cell, absent robots last), and `start` holds, per environment,
where each cell's run begins in `order` (a bincount by ``scatter_add`` and its cumulative sum):
cell c's robots are ``order[e, start[e, c] : start[e, c + 1]]``. Every pair that can touch
(distance below ``r_i + r_j <= cell_size``) lies in the same or adjacent cells.

Unlike `contacts.neighbour_candidates` (at most `cell_capacity` robots seen per cell, fixed
shapes), what reads this list can visit every robot of a cell: `cell_candidates` without a
capacity (one host sync for the largest cell), `contact_pairs`, and the Triton kernel of
`sim.triton_tick`, which loops over each neighbouring cell's actual count.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from .contacts import candidate_contacts
from .state import WorldParams


class CellList(NamedTuple):
    grid: int  # cells per side g (cells 0 .. g*g - 1; absent robots in bucket g*g)
    cell: torch.Tensor  # [E, N] long cell of each robot, cx * g + cy (absent: g * g)
    order: torch.Tensor  # [E, N] long robot rows sorted by cell (stable)
    start: torch.Tensor  # [E, g*g + 2] long: cell c is order[start[c]:start[c + 1]]


def grid_size(arena: float, cell_size: float) -> int:
    """Cells per side of the arena (as `contacts._cells`)."""
    return max(1, math.ceil(arena / cell_size))


def build_cell_list(
    pos: torch.Tensor, present: torch.Tensor, cell_size: float, arena: float
) -> CellList:
    """The cell list of positions [E, N, 2] (robots outside the arena go to its edge cells)."""
    E, N = present.shape
    g = grid_size(arena, cell_size)
    cxy = (pos / cell_size).floor().long().clamp(0, g - 1)
    cell = torch.where(present, cxy[..., 0] * g + cxy[..., 1], g * g)
    order = torch.argsort(cell, dim=1, stable=True)
    counts = torch.zeros(E, g * g + 1, dtype=torch.long, device=pos.device)
    counts.scatter_add_(1, cell, torch.ones_like(cell))
    start = torch.cat([counts.new_zeros(E, 1), counts.cumsum(1)], 1)
    return CellList(g, cell, order, start)


def cell_list_for(pos: torch.Tensor, present: torch.Tensor, params: WorldParams) -> CellList:
    return build_cell_list(pos, present, params.cell_size, params.arena)


def max_cell_count(cl: CellList) -> int:
    """The most robots in one cell (a host sync)."""
    counts = cl.start[:, 1:-1] - cl.start[:, :-2]  # cells 0 .. g*g - 1
    return int(counts.max()) if counts.numel() else 0


def cell_candidates(
    cl: CellList, present: torch.Tensor, capacity: int | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """[E, N, K] long candidate partner rows and [E, N, K] bool valid, K = 9 * capacity: the
    robots of each robot's 9 neighbouring cells (self and absent robots not valid), the format
    of `contacts.neighbour_candidates`. `capacity` None: the largest cell's count (one host
    sync), so every robot of every neighbouring cell is listed; an int: fixed shapes, and robots
    past a cell's first `capacity` are not seen from it."""
    E, N = present.shape
    dev = cl.order.device
    g = cl.grid
    M = max(1, max_cell_count(cl)) if capacity is None else capacity
    cx = torch.where(present, cl.cell // g, -2)
    cy = torch.where(present, cl.cell % g, -2)
    off = torch.arange(-1, 2, device=dev)
    nx = cx[..., None, None] + off[:, None]  # [E, N, 3, 1]
    ny = cy[..., None, None] + off[None, :]  # [E, N, 1, 3]
    inside = (nx >= 0) & (nx < g) & (ny >= 0) & (ny < g)  # [E, N, 3, 3]
    ncell = torch.where(inside, nx * g + ny, g * g).reshape(E, N * 9)  # outside: empty (see s1)
    s0 = cl.start.gather(1, ncell)
    s1 = torch.where(inside.reshape(E, N * 9), cl.start.gather(1, ncell + 1), s0)
    slot = s0[..., None] + torch.arange(M, device=dev)  # [E, N*9, M]
    ok = slot < s1[..., None]
    rows = cl.order.gather(1, slot.clamp(max=N - 1).reshape(E, -1)).reshape(E, N, 9 * M)
    ok = ok.reshape(E, N, 9 * M) & (rows != torch.arange(N, device=dev)[None, :, None])
    return rows, ok & present[..., None]


def _touching(xi, yi, ri, xj, yj, rj) -> torch.Tensor:
    """Elementwise (no reduction, so the same bits whatever the shapes): centres closer than
    the sum of the radii."""
    dx = xi - xj
    dy = yi - yj
    return torch.sqrt(dx * dx + dy * dy) < ri + rj


def contact_pairs(cl: CellList, pos: torch.Tensor, radius: torch.Tensor, present: torch.Tensor):
    """[P, 3] long (environment, i, j), i < j, in lexicographic order: every pair of present
    robots closer than r_i + r_j, found through the cell list (exact: every robot of every
    neighbouring cell; needs ``r_i + r_j <= cell_size``)."""
    E, N = present.shape
    rows, valid = cell_candidates(cl, present)
    x, y = pos[..., 0], pos[..., 1]
    flat = lambda v: v.gather(1, rows.reshape(E, -1)).reshape(rows.shape)  # noqa: E731
    near = _touching(x[..., None], y[..., None], radius[..., None], flat(x), flat(y), flat(radius))
    hit = valid & near
    hit &= rows > torch.arange(N, device=pos.device)[None, :, None]  # each pair once, i < j
    e, i, k = hit.nonzero(as_tuple=True)
    j = rows[e, i, k]
    key = (e * N + i) * N + j
    return torch.stack([e, i, j], 1)[key.argsort()]


def dense_contact_pairs(pos: torch.Tensor, radius: torch.Tensor, present: torch.Tensor):
    """`contact_pairs` over all [E, N, N] pairs (the reference for tests)."""
    N = present.shape[1]
    x, y = pos[..., 0], pos[..., 1]
    xi, yi, ri = x[..., :, None], y[..., :, None], radius[..., :, None]
    hit = _touching(xi, yi, ri, x[..., None, :], y[..., None, :], radius[..., None, :])
    hit &= present[:, :, None] & present[:, None, :]
    hit &= torch.ones(N, N, dtype=torch.bool, device=pos.device).triu(1)
    return hit.nonzero()


def robot_contacts_cell_list(
    pos, vel, radius, mass, present, params: WorldParams, capacity: int | None = None
):
    """`contacts._robot_contacts_dense`'s solver over this cell list's candidates (rebuilt every
    pass, as the reference's broad phase). `capacity` as in `cell_candidates` (None: exact)."""

    def candidates(p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return cell_candidates(cell_list_for(p, present, params), present, capacity)

    return candidate_contacts(pos, vel, radius, mass, params, candidates)
