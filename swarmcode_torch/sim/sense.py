"""Sensing: every robot's leaf statuses (and nearest / preferred grip) from the state."""

from __future__ import annotations

from typing import NamedTuple

import torch

from . import bt
from .layout import Layout
from .state import DELIVERED, Robots, State, WorldParams

_INF = 1e9


class Senses(NamedTuple):
    leaf: torch.Tensor  # [E, N, 14] leaf statuses
    best: torch.Tensor  # [E, N] flat grip index of the nearest takeable grip
    best_d: torch.Tensor  # [E, N] its distance (_INF if none)
    rand: torch.Tensor  # [E, N] flat grip index of the robot's randomly preferred grip
    rand_d: torch.Tensor  # [E, N] its distance
    gpos: torch.Tensor  # [E, H, 2] grip point positions, H = Q * G
    d_base: torch.Tensor  # [E, N]


def sense(
    state: State,
    layout: Layout,
    robots: Robots,
    compat: torch.Tensor,
    keys: torch.Tensor,
    params: WorldParams,
) -> Senses:
    """Leaf statuses of every robot from the current state (`keys`: see :func:`random_keys`)."""
    E = robots.radius.shape[0]
    base, gpos, avail, free = grip_points(state, layout, robots, params)
    avail = avail.reshape(E, gpos.shape[1])
    best, best_d, rand, rand_d = nearest_grips(state.pos, gpos, avail, free, compat, keys)

    return leaf_senses(state, params, base, gpos, best, best_d, rand, rand_d)


def nearest_grips(
    pos: torch.Tensor,
    gpos: torch.Tensor,
    avail: torch.Tensor,
    free: torch.Tensor,
    compat: torch.Tensor,
    keys: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """The robot x grip-point phase of `sense` (the Triton tick's `sense_triton` replaces it by
    its kernel's): (best, best_d, rand, rand_d) [E, N], each robot's nearest takeable grip and
    its randomly preferred one, as flat grip indices, with their distances (_INF if none), from
    positions [E, N, 2], grip points [E, H, 2], avail [E, H], free [E, N], compat [E, N, H] and
    keys [E, N, H]."""
    dist = (gpos[:, None, :, :] - pos[:, :, None, :]).norm(dim=-1)  # [E, N, H]
    valid = compat & avail[:, None, :] & free[..., None]
    dm = torch.where(valid, dist, _INF)
    best_d, best = dm.min(-1)
    score = torch.where(valid, keys, -1.0)
    rand = score.argmax(-1)
    rand_d = torch.where(
        valid.gather(-1, rand[..., None]).squeeze(-1),
        dist.gather(-1, rand[..., None]).squeeze(-1),
        _INF,
    )
    return best, best_d, rand, rand_d


def grip_points(
    state: State, layout: Layout, robots: Robots, params: WorldParams
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """What both ways of sensing (`sense`, the Triton tick's) start from: the base's centre [2],
    the grip points' positions gpos [E, H, 2], which grip points are free to take avail [E, Q, G]
    (a grip of a package that is present, not delivered, not held), which robots may take one
    free [E, N] (present, with energy, holding nothing)."""
    E = robots.radius.shape[0]
    Q, G = layout.g_effector.shape[1:]
    base = state.pos.new_tensor([params.arena / 2, params.arena / 2])
    gpos = (state.p_pos[:, :, None, :] + layout.g_offset).reshape(E, Q * G, 2)
    avail = (
        (layout.g_effector >= 0)
        & (state.holder < 0)
        & (state.p_status != DELIVERED)[..., None]
        & layout.p_present[..., None]
    )
    alive = robots.present & (state.energy > 0)
    free = alive & (state.holding < 0)
    return base, gpos, avail, free


def leaf_senses(
    state: State,
    params: WorldParams,
    base: torch.Tensor,
    gpos: torch.Tensor,
    best: torch.Tensor,
    best_d: torch.Tensor,
    rand: torch.Tensor,
    rand_d: torch.Tensor,
) -> Senses:
    """The leaf statuses of every robot from its nearest and preferred grips (`sense` and the
    Triton tick's sensing share it: only how the grips are found differs)."""
    E, N = state.holding.shape
    d_base = (state.pos - base).norm(dim=-1)
    has_target = best_d < _INF
    holding = state.holding >= 0
    S, F, R = bt.SUCCESS, bt.FAILURE, bt.RUNNING

    def cond(x):
        return torch.where(x, S, F)

    def move(fail, done):
        return torch.where(fail, F, torch.where(done, S, R))

    leaf = torch.zeros(E, N, bt.NUM_OPCODES, dtype=torch.long, device=state.pos.device)
    leaf[..., bt.COND_HAS_PACKAGE] = cond(holding)
    leaf[..., bt.COND_NEAR_PACKAGE] = cond(best_d <= params.near)
    leaf[..., bt.COND_NEAR_BASE] = cond(d_base <= params.base_radius)
    leaf[..., bt.COND_AM_I_STUCK] = cond(state.stuck >= params.stuck_ticks)
    leaf[..., bt.ACT_MOVE_TO_PACK] = move(~has_target, best_d <= params.reach)
    leaf[..., bt.ACT_MOVE_TO_BASE] = move(torch.zeros_like(holding), d_base <= params.base_radius)
    wp_done = (state.waypoint - state.pos).norm(dim=-1) <= params.reach
    leaf[..., bt.ACT_RANDOM_WALK] = move(torch.zeros_like(holding), wp_done)
    leaf[..., bt.ACT_PICK_UP] = cond(best_d <= params.reach)
    leaf[..., bt.ACT_DROP] = cond(holding)
    leaf[..., bt.ACT_MOVE_TO_RANDOM_PACK] = move(~has_target, rand_d <= params.reach)
    return Senses(leaf, best, best_d, rand, rand_d, gpos, d_base)
