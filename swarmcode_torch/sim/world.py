"""The batched foraging world: sensing, behavior-tree tick, task rules and physics.

E environments advance together; robots are ``[E, N]``, packages ``[E, P]``, grip points
``[E, P, G]`` (an individual package has one grip, at its centre), obstacles ``[E, O]``.
One call of :func:`step` is one tick for the whole batch: fixed shapes, no Python loop over
robots, packages or environments, and no host synchronisation, so it compiles to few kernels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, NamedTuple

import torch

from . import bt
from .hardware import Phenotype
from .layout import Layout
from .scenario import Scenario

GROUND, HELD, DELIVERED = 0, 1, 2
_MOVE_ACTIONS = (bt.ACT_MOVE_TO_PACK, bt.ACT_MOVE_TO_BASE, bt.ACT_RANDOM_WALK,
                 bt.ACT_MOVE_TO_RANDOM_PACK)
_INF = 1e9


@dataclass(frozen=True)
class WorldParams:
    """Physical and sensing constants (reasons for each value: docs/MODEL.md)."""

    arena: float = 20.0          # side of the square arena (m)
    base_radius: float = 1.5     # the base is a disc at the arena centre (m)
    dt: float = 0.1              # s per tick
    drag: float = 2.0            # rolling resistance, 1/s (deceleration per unit speed)
    v_cap: float = 0.6           # wheel speed limit (m/s)
    kp: float = 2.0              # position gain of the PD controller (1/s)
    kv: float = 5.0              # velocity (damping) gain (1/s)
    lift_force: float = 0.8      # N of drive force needed per kg moved (robot + load)
    reach: float = 0.35          # a package or grip point within this distance can be taken (m)
    near: float = 1.5            # COND_NEAR_PACKAGE radius (m)
    idle_power: float = 2.0      # W drawn by electronics whatever the robot does
    stuck_speed: float = 0.05    # m/s: slower than this while trying to move counts as stuck
    stuck_ticks: int = 15        # ticks of trying without moving before COND_AM_I_STUCK holds
    waypoint_period: int = 100   # ticks before a random-walk waypoint is redrawn
    collision_iters: int = 3     # relaxation passes of the robot-robot contact solver
    anchor_mass: float = 1e6     # collision mass of a robot waiting at a grip (it does not yield)
    rest_speed: float = 0.01     # static friction: slower than this (m/s), a body comes to rest
    broad_phase_min_robots: int = 500  # robot-robot contacts from a cell list at N >= this
    cell_size: float = 1.1       # broad-phase cell side (m): >= the largest contact distance 2 R_max
    cell_capacity: int = 32      # robots per cell the broad phase looks at (see cell_overflow)

    @staticmethod
    def for_scenario(s: Scenario, **kw) -> "WorldParams":
        return WorldParams(arena=s.arena, base_radius=s.base_radius, **kw)


class Robots(NamedTuple):
    """Per-robot constants of a rollout, ``[E, N]``."""

    radius: torch.Tensor
    mass: torch.Tensor
    force: torch.Tensor
    payload: torch.Tensor
    capacity: torch.Tensor
    efficiency: torch.Tensor
    effector: torch.Tensor    # long
    present: torch.Tensor     # bool; padding slots are absent
    program: torch.Tensor     # long, row of the behavior-tree table each robot runs

    @staticmethod
    def from_phenotype(ph: Phenotype, present: torch.Tensor, program: torch.Tensor) -> "Robots":
        return Robots(ph.radius, ph.mass, ph.force, ph.payload, ph.capacity, ph.efficiency,
                      ph.effector, present, program)


class State(NamedTuple):
    """Everything that changes during an episode."""

    t: torch.Tensor         # [] long tick counter
    pos: torch.Tensor       # [E, N, 2]
    vel: torch.Tensor       # [E, N, 2]
    energy: torch.Tensor    # [E, N] J left
    holding: torch.Tensor   # [E, N] long package held, -1 none
    grip: torch.Tensor      # [E, N] long grip slot held
    stuck: torch.Tensor     # [E, N] long ticks spent trying to move without moving
    waypoint: torch.Tensor  # [E, N, 2] random-walk target
    p_pos: torch.Tensor     # [E, P, 2]
    p_vel: torch.Tensor     # [E, P, 2]
    p_status: torch.Tensor  # [E, P] long GROUND / HELD / DELIVERED
    holder: torch.Tensor    # [E, P, G] long robot holding each grip, -1 none
    p_picked: torch.Tensor  # [E, P] bool ever lifted (all grips held at once)
    wp_key: torch.Tensor    # [E, N, 2] long random-walk stream of each robot (constant)


# ---------------------------------------------------------------- random numbers
_HASH_SEED, _HASH_A, _HASH_B, _MASK32 = 0x9E3779B1, 0x85EBCA77, 0xC2B2AE3D, 0xFFFFFFFF


def _finalize(x: torch.Tensor) -> torch.Tensor:
    """32-bit integer avalanche (murmur3-style) -> uniform [0, 1) float32."""
    x = x ^ (x >> 16)
    x = (x * 0x7FEB352D) & _MASK32
    x = x ^ (x >> 15)
    x = (x * 0x846CA68B) & _MASK32
    x = x ^ (x >> 16)
    return x.float() * (1.0 / 4294967296.0)


def hash_uniform(seed: torch.Tensor, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Counter-based uniform [0, 1) numbers from integer keys (broadcast); no generator state."""
    return _finalize((seed * _HASH_SEED + a * _HASH_A + b * _HASH_B) & _MASK32)


def waypoint_keys(seed: torch.Tensor, n: int) -> torch.Tensor:
    """[E, n, 2] long: the hash of (seed, robot, axis) without the tick term.

    Computed once per episode, outside the compiled tick: folded into the tick, the products of
    `arange` with 32-bit constants become integer literals that Triton rejects on CUDA.
    """
    a = torch.arange(2 * n, device=seed.device).reshape(n, 2)
    return (seed[:, None, None] * _HASH_SEED + a * _HASH_A) & _MASK32


def _waypoints(wp_key: torch.Tensor, t: torch.Tensor, params: WorldParams) -> torch.Tensor:
    """[E, N, 2] fresh random-walk waypoints for tick t: hash_uniform(seed, 2 i + axis, t)."""
    u = _finalize((wp_key + t * _HASH_B) & _MASK32)
    lo, hi = 0.5, params.arena - 0.5
    return lo + (hi - lo) * u


# ---------------------------------------------------------------- reset
def reset(layout: Layout, robots: Robots, params: WorldParams) -> State:
    """The state at tick 0: robots at their start slots with full batteries."""
    E, N = robots.radius.shape
    P, G = layout.g_effector.shape[1:]
    dev = robots.radius.device
    t = torch.zeros((), dtype=torch.long, device=dev)
    wp_key = waypoint_keys(layout.seed, N)
    return State(
        t=t, pos=layout.start.clone(), vel=torch.zeros(E, N, 2, device=dev),
        energy=torch.where(robots.present, robots.capacity, 0.0),
        holding=torch.full((E, N), -1, dtype=torch.long, device=dev),
        grip=torch.zeros(E, N, dtype=torch.long, device=dev),
        stuck=torch.zeros(E, N, dtype=torch.long, device=dev),
        waypoint=_waypoints(wp_key, t, params),
        p_pos=layout.p_pos.clone(), p_vel=torch.zeros(E, P, 2, device=dev),
        p_status=torch.full((E, P), GROUND, dtype=torch.long, device=dev),
        holder=torch.full((E, P, G), -1, dtype=torch.long, device=dev),
        p_picked=torch.zeros(E, P, dtype=torch.bool, device=dev), wp_key=wp_key,
    )


# ---------------------------------------------------------------- sensing
class Senses(NamedTuple):
    leaf: torch.Tensor      # [E, N, 14] leaf statuses
    best: torch.Tensor      # [E, N] flat grip index of the nearest takeable grip
    best_d: torch.Tensor    # [E, N] its distance (_INF if none)
    rand: torch.Tensor      # [E, N] flat grip index of the robot's randomly preferred grip
    rand_d: torch.Tensor    # [E, N] its distance
    gpos: torch.Tensor      # [E, C, 2] grip point positions, C = P * G
    d_base: torch.Tensor    # [E, N]


def compatible(layout: Layout, robots: Robots, params: WorldParams) -> torch.Tensor:
    """[E, N, C] whether each robot could take each grip (effector, size band, load)."""
    E, P, G = layout.g_effector.shape
    n_grips = (layout.g_effector >= 0).sum(-1).clamp_min(1)               # [E, P]
    load = (layout.p_mass / n_grips)[..., None].expand(E, P, G).reshape(E, 1, P * G)
    band = layout.p_band[:, :, None, :].expand(E, P, G, 2).reshape(E, 1, P * G, 2)
    r = robots.radius[..., None]
    ok = robots.effector[..., None] == layout.g_effector.reshape(E, 1, P * G)
    ok = ok & (r >= band[..., 0]) & (r <= band[..., 1])
    ok = ok & (robots.payload[..., None] >= load)
    ok = ok & (robots.force[..., None] >= params.lift_force * (robots.mass[..., None] + load))
    return ok


def capabilities(robots: Phenotype | Robots, scenario: Scenario,
                 params: WorldParams) -> torch.Tensor:
    """[..., C] bool: which of the scenario's C package classes each robot can lift, by the
    criteria of `compatible` (a grip of its effector, its radius in the class's band, payload and
    drive force for its share of the class's lightest package). A robot's capability is its
    row; distinct non-empty rows are the niches a team covers."""
    r = robots.radius[..., None]
    cols = []
    for c in scenario.packages:
        load = c.mass[0] / len(c.grips)
        grip = torch.zeros_like(robots.effector, dtype=torch.bool)
        for e in set(c.grips):
            grip = grip | (robots.effector == e)
        cols.append(grip & (robots.radius >= c.radius_band[0]) & (robots.radius <= c.radius_band[1])
                    & (robots.payload >= load)
                    & (robots.force >= params.lift_force * (robots.mass + load)))
    if not cols:
        return torch.zeros(*r.shape[:-1], 0, dtype=torch.bool, device=r.device)
    return torch.stack(cols, dim=-1)


def sense(state: State, layout: Layout, robots: Robots, compat: torch.Tensor,
          keys: torch.Tensor, params: WorldParams) -> Senses:
    """Leaf statuses of every robot from the current state (`keys`: see :func:`random_keys`)."""
    E, N = robots.radius.shape
    P, G = layout.g_effector.shape[1:]
    C = P * G
    base = state.pos.new_tensor([params.arena / 2, params.arena / 2])
    gpos = (state.p_pos[:, :, None, :] + layout.g_offset).reshape(E, C, 2)
    dist = (gpos[:, None, :, :] - state.pos[:, :, None, :]).norm(dim=-1)       # [E, N, C]
    avail = ((layout.g_effector >= 0) & (state.holder < 0)
             & (state.p_status != DELIVERED)[..., None]
             & layout.p_present[..., None]).reshape(E, 1, C)
    alive = robots.present & (state.energy > 0)
    free = alive & (state.holding < 0)
    valid = compat & avail & free[..., None]
    dm = torch.where(valid, dist, _INF)
    best_d, best = dm.min(-1)
    score = torch.where(valid, keys, -1.0)
    rand = score.argmax(-1)
    rand_d = torch.where(valid.gather(-1, rand[..., None]).squeeze(-1),
                         dist.gather(-1, rand[..., None]).squeeze(-1), _INF)

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


# ---------------------------------------------------------------- physics helpers
def _scatter_sum(values: torch.Tensor, index: torch.Tensor, size: int) -> torch.Tensor:
    """Sum values [E, N, *] into [E, size, *] by index [E, N] (index == size is dropped)."""
    E = index.shape[0]
    shape = (E, size + 1) + tuple(values.shape[2:])
    idx = index.reshape(index.shape + (1,) * (values.dim() - 2)).expand_as(values)
    return values.new_zeros(shape).scatter_add(1, idx, values)[:, :size]


def _gather(values: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """values [E, M, *] at index [E, N] (clamped into range) -> [E, N, *]."""
    idx = index.clamp(0, values.shape[1] - 1)
    idx = idx.reshape(idx.shape + (1,) * (values.dim() - 2)).expand(
        idx.shape + tuple(values.shape[2:]))
    return values.gather(1, idx)


def _cap(v: torch.Tensor, vmax: float, vmin: float = 0.0) -> torch.Tensor:
    """Limit speeds to vmax; speeds below vmin become 0 (static friction)."""
    n = v.norm(dim=-1, keepdim=True)
    return torch.where(n < vmin, 0.0, v * (vmax / n.clamp_min(vmax)))


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
    w = inv_m[:, :, None] / inv_sum                       # share of the push robot i takes
    rsum = radius[:, :, None] + radius[:, None, :]
    # Sums over partners j of (x_i - x_j) c_ij are written x_i sum_j c_ij - (c @ x)_i, so the
    # solver only ever builds [E, N, N] scalars (and one batched matmul), never [E, N, N, 2].
    for it in range(params.collision_iters):
        dx = pos[..., 0, None] - pos[:, None, :, 0]                          # [E, N, N] i - j
        dy = pos[..., 1, None] - pos[:, None, :, 1]
        d = torch.sqrt(dx * dx + dy * dy)
        inv_d = 1.0 / d.clamp_min(1e-6)
        overlap = torch.where(pair, (rsum - d).clamp_min(0), 0.0)
        c = overlap * w * inv_d
        new_pos = pos + pos * c.sum(2, keepdim=True) - torch.bmm(c, pos)
        if it == 0:
            dvx = vel[..., 0, None] - vel[:, None, :, 0]
            dvy = vel[..., 1, None] - vel[:, None, :, 1]
            vn = (dvx * dx + dvy * dy) * inv_d                                # approach < 0
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
    nx = cxy[..., 0, None, None] + off[:, None]                                 # [E, N, 3, 1]
    ny = cxy[..., 1, None, None] + off[None, :]                                 # [E, N, 1, 3]
    inside = (nx >= 0) & (nx < g) & (ny >= 0) & (ny < g)                        # [E, N, 3, 3]
    ncell = torch.where(inside, nx * g + ny, -1).reshape(E, N * 9)
    start = torch.searchsorted(sorted_cell, ncell, side="left")
    end = torch.searchsorted(sorted_cell, ncell, side="right")
    m = torch.arange(params.cell_capacity, device=dev)
    slot = start[..., None] + m                                                 # [E, N*9, M]
    ok = slot < end[..., None]                                  # outside cells: start == end
    rows = order.gather(1, slot.clamp(max=N - 1).reshape(E, -1)).reshape(E, N, -1)
    ok = ok.reshape(E, N, -1) & (rows != torch.arange(N, device=dev)[None, :, None])
    return rows, ok & present[..., None]


def _gather_rows(values: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
    """values [E, N, *] at rows [E, N, K] -> [E, N, K, *]."""
    E, N, K = rows.shape
    return _gather(values, rows.reshape(E, N * K)).reshape((E, N, K) + tuple(values.shape[2:]))


def _robot_contacts_cells(pos, vel, radius, mass, present, params: WorldParams):
    """The same contact solver as `_robot_contacts_dense`, over [E, N, K] broad-phase candidates."""
    inv_m = 1.0 / mass
    for it in range(params.collision_iters):
        # candidates are re-binned every pass: a push may carry a robot into another cell
        rows, valid = neighbour_candidates(pos, present, params)                 # [E, N, K]
        inv_sum = inv_m[..., None] + _gather_rows(inv_m, rows)
        w = inv_m[..., None] / inv_sum
        rsum = radius[..., None] + _gather_rows(radius, rows)
        pj = _gather_rows(pos, rows)                                            # [E, N, K, 2]
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
    overlap = torch.where(o_present[:, None, :], (radius[:, :, None] + o_radius[:, None, :] - d).clamp_min(0), 0.0)
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


# ---------------------------------------------------------------- one tick
def step(state: State, layout: Layout, robots: Robots, compat: torch.Tensor, keys: torch.Tensor,
         tables: torch.Tensor, params: WorldParams) -> State:
    """Advance every environment by one tick."""
    E, N = robots.radius.shape
    P, G = layout.g_effector.shape[1:]
    C = P * G
    dev = state.pos.device
    base = state.pos.new_tensor([params.arena / 2, params.arena / 2])
    s = sense(state, layout, robots, compat, keys, params)

    # --- the behavior trees
    alive = robots.present & (state.energy > 0)
    action, fired, _ = bt.lookup(tables, robots.program, s.leaf)
    action = torch.where(alive, action, bt.NOP)
    fired = fired & alive[..., None]

    holder = state.holder.reshape(E, C)
    holding, grip = state.holding, state.grip
    robot_ids = torch.arange(N, device=dev).expand(E, N)

    # --- drop: release the grip; inside the base the package is delivered
    drop = fired[..., bt.ACT_DROP] & (holding >= 0)
    my_grip = torch.where(holding >= 0, holding * G + grip, C)
    released = _scatter_sum(drop.float(), torch.where(drop, my_grip, C), C) > 0      # [E, C]
    deliver = drop & (s.d_base <= params.base_radius)
    delivered_now = _scatter_sum(deliver.float(), torch.where(deliver, holding, P), P) > 0
    delivered = (state.p_status == DELIVERED) | delivered_now                       # [E, P]
    gone = delivered.repeat_interleave(G, dim=1)
    holder = torch.where(released | gone, -1, holder)
    lost = (holding >= 0) & _gather(delivered.long(), holding).bool()
    holding = torch.where(drop | lost, -1, holding)

    # --- pick up: the nearest takeable grip in reach; ties go to the lowest robot index
    pick = fired[..., bt.ACT_PICK_UP] & (holding < 0) & (s.best_d <= params.reach)
    claim = torch.where(pick, s.best, C)
    winner = torch.full((E, C + 1), N, dtype=torch.long, device=dev).scatter_reduce(
        1, claim, robot_ids, reduce="amin")
    got = pick & (winner.gather(1, claim) == robot_ids)
    holder = torch.cat([holder, holder.new_full((E, 1), -1)], 1).scatter(
        1, torch.where(got, s.best, C), robot_ids)[:, :C]
    holding = torch.where(got, s.best // G, holding)
    grip = torch.where(got, s.best % G, grip)

    holder3 = holder.reshape(E, P, G)
    exists = layout.g_effector >= 0
    held_any = (holder3 >= 0).any(-1)
    lifted = ((holder3 >= 0) | ~exists).all(-1) & exists.any(-1) & ~delivered
    p_status = torch.where(delivered, DELIVERED, torch.where(held_any, HELD, GROUND))
    p_picked = state.p_picked | lifted

    # --- where each robot wants to go
    target = state.pos
    target = torch.where((action == bt.ACT_MOVE_TO_PACK)[..., None] & (s.best_d < _INF)[..., None],
                         _gather(s.gpos, s.best), target)
    target = torch.where((action == bt.ACT_MOVE_TO_RANDOM_PACK)[..., None] & (s.rand_d < _INF)[..., None],
                         _gather(s.gpos, s.rand), target)
    target = torch.where((action == bt.ACT_MOVE_TO_BASE)[..., None], base.expand(E, N, 2), target)
    target = torch.where((action == bt.ACT_RANDOM_WALK)[..., None], state.waypoint, target)

    # --- PD control (cascaded: position error -> desired velocity -> force), force-limited
    carrying = holding >= 0
    n_grips = exists.sum(-1).clamp_min(1)
    share = torch.where(carrying, _gather(layout.p_mass / n_grips, holding), 0.0)
    m_ctrl = robots.mass + share
    v_des = _cap(params.kp * (target - state.pos), params.v_cap)
    f_cmd = m_ctrl[..., None] * (params.kv * (v_des - state.vel) + params.drag * v_des)
    f_max = torch.where(alive, robots.force, 0.0)[..., None]
    f_cmd = f_cmd * (f_max / f_cmd.norm(dim=-1, keepdim=True).clamp_min(1e-9)).clamp(max=1.0)

    # --- free robots: semi-implicit Euler
    vel = _cap(state.vel + params.dt * (f_cmd / robots.mass[..., None] - params.drag * state.vel),
               params.v_cap, params.rest_speed)
    pos = state.pos + params.dt * vel

    # --- lifted packages move as one rigid body with their carriers
    in_lifted = carrying & _gather(lifted.long(), holding).bool()
    pidx = torch.where(in_lifted, holding, P)
    f_pkg = _scatter_sum(f_cmd, pidx, P)
    m_pkg = layout.p_mass + _scatter_sum(robots.mass, pidx, P)
    p_vel = torch.where(lifted[..., None],
                        _cap(state.p_vel + params.dt * (f_pkg / m_pkg[..., None] - params.drag * state.p_vel),
                             params.v_cap, params.rest_speed), 0.0)
    p_pos = state.p_pos + params.dt * p_vel
    g_off = _gather(layout.g_offset.reshape(E, C, 2), holding * G + grip)
    pos = torch.where(carrying[..., None], _gather(p_pos, holding) + g_off, pos)
    vel = torch.where(carrying[..., None], _gather(p_vel, holding), vel)

    # --- contacts; carriers pass their correction on to the package they hold
    waiting = carrying & ~in_lifted
    m_col = torch.where(waiting, params.anchor_mass, robots.mass + share)
    pos_c, vel_c = collide(pos, vel, robots.radius, m_col, robots.present, layout.o_pos,
                           layout.o_radius, layout.o_present, params)
    cnt = _scatter_sum(torch.ones_like(robots.mass), pidx, P).clamp_min(1)[..., None]
    p_pos = p_pos + torch.where(lifted[..., None], _scatter_sum(pos_c - pos, pidx, P) / cnt, 0.0)
    p_vel = torch.where(lifted[..., None], _scatter_sum(vel_c, pidx, P) / cnt, p_vel)
    pos = torch.where(carrying[..., None], _gather(p_pos, holding) + g_off, pos_c)
    vel = torch.where(carrying[..., None], _gather(p_vel, holding), vel_c)

    # --- energy: mechanical power through the motor efficiency, plus idle draw
    p_mech = (f_cmd * vel).sum(-1).clamp_min(0)
    used = params.dt * (p_mech / robots.efficiency + params.idle_power)
    energy = torch.where(robots.present, (state.energy - used).clamp_min(0), 0.0)

    # --- stuck detection and random-walk waypoints
    moving = torch.zeros_like(alive)
    for a in _MOVE_ACTIONS:
        moving = moving | (action == a)
    trying = moving & ((target - state.pos).norm(dim=-1) > params.reach)
    slow = (pos - state.pos).norm(dim=-1) < params.stuck_speed * params.dt
    stuck = torch.where(trying & slow, state.stuck + 1, 0)
    t = state.t + 1
    redraw = ((state.waypoint - pos).norm(dim=-1) <= params.reach) | (t % params.waypoint_period == 0)
    waypoint = torch.where(redraw[..., None], _waypoints(state.wp_key, t, params), state.waypoint)

    # contiguous, like reset()'s holder: a strided view here would make a compiled step (which
    # guards on input strides) compile a second time on its second call
    return State(t, pos, vel, energy, holding, grip, stuck, waypoint, p_pos, p_vel, p_status,
                 holder.reshape(E, P, G).contiguous(), p_picked, state.wp_key)


# ---------------------------------------------------------------- outcome of an episode
def episode_metrics(state: State, layout: Layout, robots: Robots, params: WorldParams) -> dict:
    """Per-environment results ``[E]`` that the fitness needs, from the final state."""
    base = state.pos.new_tensor([params.arena / 2, params.arena / 2])
    present = robots.present.float()
    n_robots = present.sum(-1).clamp_min(1)
    collab = layout.p_collab & layout.p_present
    indiv = ~layout.p_collab & layout.p_present
    done = state.p_status == DELIVERED
    n_grips = (layout.g_effector >= 0).sum(-1)
    energy_pct = 100.0 * state.energy / robots.capacity.clamp_min(1e-9)
    mean_final = (energy_pct * present).sum(-1) / n_robots
    d_base = (state.pos - base).norm(dim=-1)
    prox = torch.where(state.holding >= 0, 10.0 / (1.0 + 0.1 * d_base), 0.0) * present
    d0 = (layout.p_pos - base).norm(dim=-1).clamp_min(1e-6)
    d1 = (state.p_pos - base).norm(dim=-1)
    progress = torch.where(done, 1.0, ((d0 - d1) / d0).clamp(0, 1))
    n_pk = layout.p_present.float().sum(-1).clamp_min(1)
    return {
        "delivered_individual": (done & indiv).sum(-1).float(),
        "delivered_collab": (done & collab).sum(-1).float(),
        "grips_delivered": torch.where(done & collab, n_grips, 0).sum(-1).float(),
        "picked_individual": (state.p_picked & indiv).sum(-1).float(),
        "picked_collab": (state.p_picked & collab).sum(-1).float(),
        "mean_final_energy": mean_final,
        "energy_used": 100.0 - mean_final,
        "proximity": prox.sum(-1) / n_robots,
        "closeness": (progress * layout.p_present).sum(-1) / n_pk,
    }


def random_keys(layout: Layout, n: int) -> torch.Tensor:
    """[E, N, C] each robot's fixed random preference for each grip (ACT_MOVE_TO_RANDOM_PACK
    goes to the takeable grip it prefers most), drawn from the environment's seed."""
    E, P, G = layout.g_effector.shape
    m = max(n, P * G)
    idx = torch.arange(m, device=layout.seed.device)
    u = hash_uniform(layout.seed[:, None], idx, torch.full_like(idx, -7))
    return torch.frac(u[:, :n, None] + u[:, None, :P * G] * 7.31)


class CompiledStep:
    """`torch.compile(step)`, falling back to eager `step` (with a warning) when the first call
    cannot compile, e.g. on a machine without the C++ compiler that inductor's CPU backend needs."""

    def __init__(self, **compile_kwargs):
        self.compiled = torch.compile(step, dynamic=False, **compile_kwargs)
        self.fn = None
        self.error: Exception | None = None

    def __call__(self, *args):
        if self.fn is None:
            try:
                out = self.compiled(*args)
                self.fn = self.compiled
                return out
            except Exception as e:  # noqa: BLE001 - any compiler failure means: run eager
                import warnings

                self.error, self.fn = e, step
                lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()
                         and not ln.strip().startswith(("Set TORCH", "For even more developer"))]
                parts = [lines[0]] + ([lines[-1]] if len(lines) > 1 else []) if lines else []
                why = f"{type(e).__name__}: {' ... '.join(p[:160] for p in parts)}" \
                    if parts else type(e).__name__
                warnings.warn(f"torch.compile failed ({why}); running the tick eagerly",
                              RuntimeWarning, stacklevel=2)
        return self.fn(*args)


class CudaGraphTicks:
    """Run a rollout's ticks as replays of one captured CUDA graph of `ticks_per_graph` ticks.

    `step_fn` (typically a compiled `step`) is warmed up on a side stream, then captured with
    `torch.cuda.graph` on static copies of the state and of every input; each tick's output
    state is copied back into the static state inside the graph. A later rollout with the same
    shapes and params copies its inputs into the static buffers and replays: one launch per
    `ticks_per_graph` ticks instead of one per kernel. Different shapes or params recapture.
    Pass it as `step_fn` to `rollout`. CUDA only.
    """

    def __init__(self, step_fn: Callable | None = None, ticks_per_graph: int = 10,
                 required: bool = True):
        if not torch.cuda.is_available():
            raise RuntimeError("CUDA graphs need a CUDA device")
        if ticks_per_graph < 1:
            raise ValueError("ticks_per_graph must be >= 1")
        # the eager tick makes small host-to-device copies, which a capture does not allow
        self.step_fn = step_fn if step_fn is not None else CompiledStep()
        self.k = ticks_per_graph
        self.key = None
        self.graph: torch.cuda.CUDAGraph | None = None
        # required: a tick that fails to compile is an error; otherwise the ticks run one by one
        # with the step's eager fallback
        self.required = required
        self.disabled = False

    def __call__(self, *args):  # a single tick, outside any graph
        return self.step_fn(*args)

    @staticmethod
    def _tensors(state, inputs) -> list[torch.Tensor]:
        layout, robots, compat, keys, tables = inputs
        return [*state, *layout, *robots, compat, keys, tables]

    def _capture(self, state: State, inputs: tuple, params: WorldParams) -> None:
        if any(t.device.type != "cuda" for t in self._tensors(state, inputs)):
            raise ValueError("CudaGraphTicks needs every state and input tensor on the GPU")
        layout, robots, compat, keys, tables = inputs
        self.state = State(*(t.clone() for t in state))
        self.inputs = (Layout(*(t.clone() for t in layout)), Robots(*(t.clone() for t in robots)),
                       compat.clone(), keys.clone(), tables.clone())

        def ticks(n: int) -> None:
            for _ in range(n):
                out = self.step_fn(self.state, *self.inputs, params)
                for a, b in zip(self.state, out):
                    if a is not b:
                        a.copy_(b)

        side = torch.cuda.Stream()
        side.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(side):
            ticks(2)                        # compile and allocate outside the capture
        torch.cuda.current_stream().wait_stream(side)
        if isinstance(self.step_fn, CompiledStep) and self.step_fn.error is not None:
            if self.required:
                raise RuntimeError("CudaGraphTicks needs the compiled tick, and compiling "
                                   f"failed: {self.step_fn.error}")
            self.disabled = True
            return
        self.graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(self.graph):
            ticks(self.k)

    def run_ticks(self, state: State, inputs: tuple, params: WorldParams, ticks: int) -> State:
        """`ticks` ticks from `state`; inputs = (layout, robots, compat, keys, tables)."""
        key = (tuple((t.shape, t.dtype, t.device) for t in self._tensors(state, inputs)), params)
        if key != self.key and not self.disabled:
            self._capture(state, inputs, params)
            self.key = key
        if self.disabled:  # compiling failed and graphs were optional: tick by tick
            for _ in range(ticks):
                state = self.step_fn(state, *inputs, params)
            return state
        for a, b in zip(self._tensors(self.state, self.inputs), self._tensors(state, inputs)):
            a.copy_(b)
        for _ in range(ticks // self.k):
            self.graph.replay()
        out = State(*(t.clone() for t in self.state))
        for _ in range(ticks % self.k):
            out = self.step_fn(out, *self.inputs, params)
        return out


def rollout(layout: Layout, robots: Robots, tables: torch.Tensor, params: WorldParams,
            ticks: int, step_fn: Callable | None = None, return_state: bool = False):
    """Run `ticks` ticks of every environment; the per-environment metrics (and final state)."""
    compat = compatible(layout, robots, params)
    keys = random_keys(layout, robots.radius.shape[1])
    state = reset(layout, robots, params)
    fn = step_fn or step
    if isinstance(fn, CudaGraphTicks):
        state = fn.run_ticks(state, (layout, robots, compat, keys, tables), params, ticks)
    else:
        for _ in range(ticks):
            state = fn(state, layout, robots, compat, keys, tables, params)
    m = episode_metrics(state, layout, robots, params)
    return (m, state) if return_state else m
