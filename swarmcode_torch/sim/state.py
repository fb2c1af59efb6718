"""The world's data: constants, per-robot constants, the state of an episode and its reset,
the per-episode tick inputs (grip compatibility, random keys) and the counter-based hashing.

E environments advance together; robots are ``[E, N]``, packages ``[E, Q]``, grip points
``[E, Q, G]`` (an individual package has one grip, at its centre), obstacles ``[E, O]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import torch

from .hardware import Phenotype
from .layout import Layout
from .scenario import Scenario

GROUND, HELD, DELIVERED = 0, 1, 2


@dataclass(frozen=True)
class WorldParams:
    """Physical and sensing constants (reasons for each value: docs/MODEL.md)."""

    arena: float = 20.0  # side of the square arena (m)
    base_radius: float = 1.5  # the base is a disc at the arena centre (m)
    dt: float = 0.1  # s per tick
    drag: float = 2.0  # rolling resistance, 1/s (deceleration per unit speed)
    v_cap: float = 0.6  # wheel speed limit (m/s)
    kp: float = 2.0  # position gain of the PD controller (1/s)
    kv: float = 5.0  # velocity (damping) gain (1/s)
    lift_force: float = 0.8  # N of drive force needed per kg moved (robot + load)
    reach: float = 0.35  # a package or grip point within this distance can be taken (m)
    near: float = 1.5  # COND_NEAR_PACKAGE radius (m)
    idle_power: float = 2.0  # W drawn by electronics whatever the robot does
    stuck_speed: float = 0.05  # m/s: slower than this while trying to move counts as stuck
    stuck_ticks: int = 15  # ticks of trying without moving before COND_AM_I_STUCK holds
    waypoint_period: int = 100  # ticks before a random-walk waypoint is redrawn
    collision_iters: int = 3  # relaxation passes of the robot-robot contact solver
    anchor_mass: float = 1e6  # collision mass of a robot waiting at a grip (it does not yield)
    rest_speed: float = 0.01  # static friction: slower than this (m/s), a body comes to rest
    broad_phase_min_robots: int = 500  # robot-robot contacts from a cell list at N >= this
    cell_size: float = 1.1  # broad-phase cell side (m): >= the largest contact distance,
    # 2 R_max
    cell_capacity: int = 32  # robots per cell the broad phase looks at (see cell_overflow)

    @staticmethod
    def for_scenario(s: Scenario, **kw) -> WorldParams:
        return WorldParams(arena=s.arena, base_radius=s.base_radius, **kw)


class Robots(NamedTuple):
    """Per-robot constants of a rollout, ``[E, N]``."""

    radius: torch.Tensor
    mass: torch.Tensor
    force: torch.Tensor
    payload: torch.Tensor
    capacity: torch.Tensor
    efficiency: torch.Tensor
    effector: torch.Tensor  # long
    present: torch.Tensor  # bool; padding slots are absent
    program: torch.Tensor  # long, row of the behavior-tree table each robot runs

    @staticmethod
    def from_phenotype(ph: Phenotype, present: torch.Tensor, program: torch.Tensor) -> Robots:
        return Robots(
            ph.radius,
            ph.mass,
            ph.force,
            ph.payload,
            ph.capacity,
            ph.efficiency,
            ph.effector,
            present,
            program,
        )


class State(NamedTuple):
    """Everything that changes during an episode."""

    t: torch.Tensor  # [] long tick counter
    pos: torch.Tensor  # [E, N, 2]
    vel: torch.Tensor  # [E, N, 2]
    energy: torch.Tensor  # [E, N] J left
    holding: torch.Tensor  # [E, N] long package held, -1 none
    grip: torch.Tensor  # [E, N] long grip slot held
    stuck: torch.Tensor  # [E, N] long ticks spent trying to move without moving
    waypoint: torch.Tensor  # [E, N, 2] random-walk target
    p_pos: torch.Tensor  # [E, Q, 2]
    p_vel: torch.Tensor  # [E, Q, 2]
    p_status: torch.Tensor  # [E, Q] long GROUND / HELD / DELIVERED
    holder: torch.Tensor  # [E, Q, G] long robot holding each grip, -1 none
    p_picked: torch.Tensor  # [E, Q] bool ever lifted (all grips held at once)
    wp_key: torch.Tensor  # [E, N, 2] long random-walk stream of each robot (constant)


class TickInputs(NamedTuple):
    """What the tick reads besides the state and the params, constant over an episode:
    ``step(state, *inputs, params)``."""

    layout: Layout
    robots: Robots
    compat: torch.Tensor  # [E, N, H] bool, `compatible`
    keys: torch.Tensor  # [E, N, H] float, `random_keys`
    tables: torch.Tensor  # behavior-tree tables, `bt.build_tables`


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
    Q, G = layout.g_effector.shape[1:]
    dev = robots.radius.device
    t = torch.zeros((), dtype=torch.long, device=dev)
    wp_key = waypoint_keys(layout.seed, N)
    return State(
        t=t,
        pos=layout.start.clone(),
        vel=torch.zeros(E, N, 2, device=dev),
        energy=torch.where(robots.present, robots.capacity, 0.0),
        holding=torch.full((E, N), -1, dtype=torch.long, device=dev),
        grip=torch.zeros(E, N, dtype=torch.long, device=dev),
        stuck=torch.zeros(E, N, dtype=torch.long, device=dev),
        waypoint=_waypoints(wp_key, t, params),
        p_pos=layout.p_pos.clone(),
        p_vel=torch.zeros(E, Q, 2, device=dev),
        p_status=torch.full((E, Q), GROUND, dtype=torch.long, device=dev),
        holder=torch.full((E, Q, G), -1, dtype=torch.long, device=dev),
        p_picked=torch.zeros(E, Q, dtype=torch.bool, device=dev),
        wp_key=wp_key,
    )


# ---------------------------------------------------------------- per-episode constants
def compatible(layout: Layout, robots: Robots, params: WorldParams) -> torch.Tensor:
    """[E, N, H] whether each robot could take each grip (effector, size band, load)."""
    E, Q, G = layout.g_effector.shape
    n_grips = (layout.g_effector >= 0).sum(-1).clamp_min(1)  # [E, Q]
    load = (layout.p_mass / n_grips)[..., None].expand(E, Q, G).reshape(E, 1, Q * G)
    band = layout.p_band[:, :, None, :].expand(E, Q, G, 2).reshape(E, 1, Q * G, 2)
    r = robots.radius[..., None]
    ok = robots.effector[..., None] == layout.g_effector.reshape(E, 1, Q * G)
    ok = ok & (r >= band[..., 0]) & (r <= band[..., 1])
    ok = ok & (robots.payload[..., None] >= load)
    ok = ok & (robots.force[..., None] >= params.lift_force * (robots.mass[..., None] + load))
    return ok


def capabilities(
    robots: Phenotype | Robots, scenario: Scenario, params: WorldParams
) -> torch.Tensor:
    """[..., U] bool: which of the scenario's U package classes each robot can lift, by the
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
        cols.append(
            grip
            & (robots.radius >= c.radius_band[0])
            & (robots.radius <= c.radius_band[1])
            & (robots.payload >= load)
            & (robots.force >= params.lift_force * (robots.mass + load))
        )
    if not cols:
        return torch.zeros(*r.shape[:-1], 0, dtype=torch.bool, device=r.device)
    return torch.stack(cols, dim=-1)


def random_keys(layout: Layout, n: int) -> torch.Tensor:
    """[E, N, H] each robot's fixed random preference for each grip (ACT_MOVE_TO_RANDOM_PACK
    goes to the takeable grip it prefers most), drawn from the environment's seed."""
    E, Q, G = layout.g_effector.shape
    m = max(n, Q * G)
    idx = torch.arange(m, device=layout.seed.device)
    u = hash_uniform(layout.seed[:, None], idx, torch.full_like(idx, -7))
    return torch.frac(u[:, :n, None] + u[:, None, : Q * G] * 7.31)
