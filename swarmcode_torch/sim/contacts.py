"""Contacts: robot-robot (dense pairs, or a cell-list broad phase for large swarms),
robot-obstacle and robot-wall, resolved elastically."""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

from .state import WorldParams


def _gather(values: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """values [E, M, *] at index [E, N] (clamped into range) -> [E, N, *]."""
    idx = index.clamp(0, values.shape[1] - 1)
    idx = idx.reshape(idx.shape + (1,) * (values.dim() - 2)).expand(
        idx.shape + tuple(values.shape[2:])
    )
    return values.gather(1, idx)


def collide(pos, vel, radius, mass, present, o_pos, o_radius, o_present, params: WorldParams):
    """Resolve robot-robot, robot-obstacle and robot-wall contacts (elastic, restitution 1).

    Robot pairs exchange equal and opposite impulses along the contact normal (momentum is
    conserved) and are pushed apart in inverse proportion to their masses.
    """
    N = pos.shape[1]
    if N >= params.broad_phase_min_robots:
        pos, vel = _robot_contacts_cells(pos, vel, radius, mass, present, params)
    else:
        pos, vel = _robot_contacts_dense(pos, vel, radius, mass, present, params)
    return _static_contacts(pos, vel, radius, o_pos, o_radius, o_present, params)


def _robot_contacts_dense(pos, vel, radius, mass, present, params: WorldParams):
    """Robot-robot contacts over all [E, N, N] pairs (right for tens to hundreds of robots)."""
    N = pos.shape[1]
    eye = torch.eye(N, dtype=torch.bool, device=pos.device)
    pair = present[:, :, None] & present[:, None, :] & ~eye
    inv_m = 1.0 / mass
    inv_sum = inv_m[:, :, None] + inv_m[:, None, :]
    w = inv_m[:, :, None] / inv_sum  # share of the push robot i takes
    rsum = radius[:, :, None] + radius[:, None, :]
    # Sums over partners j of (x_i - x_j) c_ij are written x_i sum_j c_ij - (c @ x)_i, so the
    # solver only ever builds [E, N, N] scalars (and one batched matmul), never [E, N, N, 2].
    for it in range(params.collision_iters):
        dx = pos[..., 0, None] - pos[:, None, :, 0]  # [E, N, N] i - j
        dy = pos[..., 1, None] - pos[:, None, :, 1]
        d = torch.sqrt(dx * dx + dy * dy)
        inv_d = 1.0 / d.clamp_min(1e-6)
        overlap = torch.where(pair, (rsum - d).clamp_min(0), 0.0)
        c = overlap * w * inv_d
        new_pos = pos + pos * c.sum(2, keepdim=True) - torch.bmm(c, pos)
        if it == 0:
            dvx = vel[..., 0, None] - vel[:, None, :, 0]
            dvy = vel[..., 1, None] - vel[:, None, :, 1]
            vn = (dvx * dx + dvy * dy) * inv_d  # approach < 0
            j = torch.where((overlap > 0) & (vn < 0), -2.0 * vn / inv_sum, 0.0)
            k = j * inv_d
            vel = vel + inv_m[..., None] * (pos * k.sum(2, keepdim=True) - torch.bmm(k, pos))
        pos = new_pos
    return pos, vel


def _cells(pos, present, params: WorldParams):
    """Cells per side g, [E, N, 2] cell coordinates, [E, N] cell ids (absent robots: g * g)."""
    g = max(1, math.ceil(params.arena / params.cell_size))
    cxy = (pos / params.cell_size).floor().long().clamp(0, g - 1)
    return g, cxy, torch.where(present, cxy[..., 0] * g + cxy[..., 1], g * g)


def cell_overflow(pos, present, params: WorldParams) -> torch.Tensor:
    """[E] bool: some broad-phase cell holds more than `cell_capacity` robots (contacts could be
    missed there). A check for tests and diagnostics; the tick does not call it."""
    g, _, cell = _cells(pos, present, params)
    counts = torch.zeros(cell.shape[0], g * g + 1, dtype=torch.long, device=pos.device)
    counts.scatter_add_(1, cell, torch.ones_like(cell))
    return counts[:, :-1].max(1).values > params.cell_capacity


def neighbour_candidates(pos, present, params: WorldParams) -> tuple[torch.Tensor, torch.Tensor]:
    """Cell-list broad phase: [E, N, 2] positions -> ([E, N, K] long candidate partner rows,
    [E, N, K] bool valid), K = 9 * cell_capacity.

    Robots are binned into square cells of side `cell_size` (at least the largest contact
    distance, so every pair that can touch lies in the same or adjacent cells); each robot's
    candidates are the first `cell_capacity` robots of each of its 9 neighbouring cells (sorted
    by cell, so this needs no Python loop and has fixed shapes). Self and absent robots are not
    valid. Robots past a cell's `cell_capacity` (by row order) are not seen from that cell: a
    hexagonal packing of touching R_MIN robots puts 20 centres in a 1.1 m cell, so 32 leaves room
    for the small overlaps the solver allows; `cell_overflow` tells whether a state exceeds it.
    """
    E, N = pos.shape[:2]
    dev = pos.device
    g, cxy, cell = _cells(pos, present, params)
    sorted_cell, order = torch.sort(cell, dim=1, stable=True)
    off = torch.arange(-1, 2, device=dev)
    nx = cxy[..., 0, None, None] + off[:, None]  # [E, N, 3, 1]
    ny = cxy[..., 1, None, None] + off[None, :]  # [E, N, 1, 3]
    inside = (nx >= 0) & (nx < g) & (ny >= 0) & (ny < g)  # [E, N, 3, 3]
    ncell = torch.where(inside, nx * g + ny, -1).reshape(E, N * 9)
    start = torch.searchsorted(sorted_cell, ncell, side="left")
    end = torch.searchsorted(sorted_cell, ncell, side="right")
    m = torch.arange(params.cell_capacity, device=dev)
    slot = start[..., None] + m  # [E, N*9, M]
    ok = slot < end[..., None]  # outside cells: start == end
    rows = order.gather(1, slot.clamp(max=N - 1).reshape(E, -1)).reshape(E, N, -1)
    ok = ok.reshape(E, N, -1) & (rows != torch.arange(N, device=dev)[None, :, None])
    return rows, ok & present[..., None]


def _gather_rows(values: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
    """values [E, N, *] at rows [E, N, K] -> [E, N, K, *]."""
    E, N, K = rows.shape
    return _gather(values, rows.reshape(E, N * K)).reshape((E, N, K) + tuple(values.shape[2:]))


def _robot_contacts_cells(pos, vel, radius, mass, present, params: WorldParams):
    """The same contact solver as `_robot_contacts_dense`, over [E, N, K] broad-phase candidates."""
    return candidate_contacts(
        pos, vel, radius, mass, params, lambda p: neighbour_candidates(p, present, params)
    )


def candidate_contacts(
    pos,
    vel,
    radius,
    mass,
    params: WorldParams,
    candidates: Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]],
):
    """`_robot_contacts_dense`'s solver over broad-phase candidates: `candidates(pos)` -> each
    robot's candidate partner rows [E, N, K] and which are valid [E, N, K] bool, asked again
    every pass (a push may carry a robot into another cell). The broad phase of `collide`
    (`neighbour_candidates`) and the cell list's (`cell_list.robot_contacts_cell_list`)."""
    inv_m = 1.0 / mass
    for it in range(params.collision_iters):
        rows, valid = candidates(pos)  # [E, N, K]
        inv_sum = inv_m[..., None] + _gather_rows(inv_m, rows)
        w = inv_m[..., None] / inv_sum
        rsum = radius[..., None] + _gather_rows(radius, rows)
        pj = _gather_rows(pos, rows)  # [E, N, K, 2]
        diff = pos[:, :, None, :] - pj
        d = diff.norm(dim=-1)
        inv_d = 1.0 / d.clamp_min(1e-6)
        overlap = torch.where(valid, (rsum - d).clamp_min(0), 0.0)
        new_pos = pos + ((overlap * w * inv_d)[..., None] * diff).sum(2)
        if it == 0:
            vn = ((vel[:, :, None, :] - _gather_rows(vel, rows)) * diff).sum(-1) * inv_d
            j = torch.where((overlap > 0) & (vn < 0), -2.0 * vn / inv_sum, 0.0)
            vel = vel + inv_m[..., None] * ((j * inv_d)[..., None] * diff).sum(2)
        pos = new_pos
    return pos, vel


def _static_contacts(pos, vel, radius, o_pos, o_radius, o_present, params: WorldParams):
    """Robot-obstacle and robot-wall contacts."""
    # static obstacles: push out, reflect the normal velocity
    diff = pos[:, :, None, :] - o_pos[:, None, :, :]
    d = diff.norm(dim=-1)
    n = diff / d.clamp_min(1e-6)[..., None]
    overlap = torch.where(
        o_present[:, None, :], (radius[:, :, None] + o_radius[:, None, :] - d).clamp_min(0), 0.0
    )
    pos = pos + (n * overlap[..., None]).sum(2)
    vn = (vel[:, :, None, :] * n).sum(-1)
    hit = (overlap > 0) & (vn < 0)
    vel = vel - (n * torch.where(hit, 2 * vn, 0.0)[..., None]).sum(2)

    # walls
    r = radius[..., None]
    lo, hi = r, params.arena - r
    out_lo, out_hi = pos < lo, pos > hi
    vel = torch.where((out_lo & (vel < 0)) | (out_hi & (vel > 0)), -vel, vel)
    pos = torch.minimum(torch.maximum(pos, lo), hi)
    return pos, vel
