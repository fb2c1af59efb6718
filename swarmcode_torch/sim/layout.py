"""Random environments: obstacles, packages and robot start positions for E worlds at once.

A layout is everything about an environment that does not depend on the robots placed in it,
so the focal and baseline trials of an evaluation can share it exactly.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import torch

from .hardware import R_MAX
from .scenario import Scenario

_CANDIDATES = 32  # rejection sampling: candidate positions drawn per object


class Layout(NamedTuple):
    """Robot-independent part of E environments (leading dimension E)."""

    p_present: torch.Tensor  # [E, Q] bool
    p_pos: torch.Tensor  # [E, Q, 2] initial package positions
    p_mass: torch.Tensor  # [E, Q]
    p_band: torch.Tensor  # [E, Q, 2] robot radii that may lift it
    p_size: torch.Tensor  # [E, Q] package radius
    p_collab: torch.Tensor  # [E, Q] bool
    g_effector: torch.Tensor  # [E, Q, G] long, -1 where the grip does not exist
    g_offset: torch.Tensor  # [E, Q, G, 2] grip point relative to the package centre
    o_pos: torch.Tensor  # [E, O, 2]
    o_radius: torch.Tensor  # [E, O]
    o_present: torch.Tensor  # [E, O] bool
    start: torch.Tensor  # [E, N, 2] robot start positions
    seed: torch.Tensor  # [E] long, seeds the in-episode hash random numbers

    def select(self, idx: torch.Tensor) -> Layout:
        """Environments `idx` (e.g. the same layout repeated for focal and baseline trials)."""
        return Layout(*(t[idx] for t in self))


def spawn_slots(n: int, spacing: float, device=None) -> torch.Tensor:
    """[n, 2] points of a sunflower spiral around the origin, at least `spacing` apart."""
    k = torch.arange(n, dtype=torch.float64, device=device)
    golden = math.pi * (3.0 - math.sqrt(5.0))
    pts = torch.stack(
        [torch.sqrt(k + 0.5) * torch.cos(k * golden), torch.sqrt(k + 0.5) * torch.sin(k * golden)],
        -1,
    )
    if n > 1:
        d = torch.cdist(pts, pts) + torch.eye(n, dtype=pts.dtype, device=device) * 1e9
        pts = pts * (spacing / d.min())
    return pts.float()


@functools.lru_cache(maxsize=64)
def _spawn_constants(n: int, spacing: float, device: torch.device) -> tuple[torch.Tensor, float]:
    """`spawn_slots(n, spacing, device)` (never written to) and their largest distance from the
    origin, read on the host: built once per (n, spacing, device), not once per call of
    `make_layouts` (the distance read a device sync each)."""
    slots = spawn_slots(n, spacing, device)
    return slots, float(slots.norm(dim=-1).max())


@functools.lru_cache(maxsize=16)
def _arena_constants(
    arena: float, device: torch.device
) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
    """The arena's centre [2] and the ranks of the candidates [1, _CANDIDATES, 1] that
    `_first_valid` picks by: a valid one's (K + 1, K, ..., 2, the first highest) and an invalid
    one's (0, ..., 0, 1: the last highest) (built once per arena and device, never written
    to)."""
    centre = torch.tensor([arena / 2, arena / 2], device=device)
    valid = torch.arange(_CANDIDATES + 1, 1, -1, device=device)[None, :, None]
    invalid = (torch.arange(_CANDIDATES, device=device) == _CANDIDATES - 1).long()[None, :, None]
    return centre, (valid, invalid)


def _first_valid(
    cand: torch.Tensor, ok: torch.Tensor, ranks: tuple[torch.Tensor, torch.Tensor]
) -> torch.Tensor:
    """cand [E, K, M, 2], ok [E, K, M], ranks (`_arena_constants`) -> [E, M, 2]: the first
    valid candidate (else the last): the highest rank, every valid one's above every invalid
    one's."""
    e, k, m, _ = cand.shape
    pick = torch.where(ok, *ranks).argmax(1)
    return torch.take_along_dim(cand, pick.view(e, 1, m, 1), 1).view(e, m, 2)


class _Packages(NamedTuple):
    """The per-package constants of a scenario's package classes, one row per package [Q]."""

    d_lo: torch.Tensor  # nearest distance from the arena's centre
    d_span: torch.Tensor  # farthest less nearest
    d_scale: torch.Tensor  # d_span, at least 1e-6
    m_lo: torch.Tensor  # lightest mass
    m_hi: torch.Tensor  # heaviest
    m_span: torch.Tensor  # m_hi - m_lo
    weighted: torch.Tensor  # bool: mass by distance (else uniform)
    size: torch.Tensor
    clear: torch.Tensor  # [Q, 1] size + room for a robot at each grip
    band: torch.Tensor  # [Q, 2] robot radii that may lift it
    collab: torch.Tensor  # bool
    g_effector: torch.Tensor  # [Q, G] long, -1 where the grip does not exist
    g_x: torch.Tensor  # [Q, G] grip offsets before the ring's random turn
    g_y: torch.Tensor  # [Q, G]


@functools.lru_cache(maxsize=16)
def _package_constants(packages: tuple, G: int, device: torch.device) -> _Packages:
    """`_Packages` of a scenario's package classes (built once per scenario and device, never
    written to)."""
    rows = [c for c in packages for _ in range(c.count)]
    Q = len(rows)

    def col(values: list) -> torch.Tensor:
        return torch.tensor(values, device=device)

    g_eff = torch.full((Q, G), -1, dtype=torch.long)  # built on the CPU
    g_off = torch.zeros(Q, G, 2)
    for i, c in enumerate(rows):
        k = len(c.grips)
        g_eff[i, :k] = torch.tensor(c.grips)
        if c.kind == "collab":
            a = torch.arange(k) * (2 * math.pi / k)
            g_off[i, :k] = (c.size + 0.1) * torch.stack([a.cos(), a.sin()], -1)
    g_off = g_off.to(device)
    d_lo, d_hi = col([c.distance[0] for c in rows]), col([c.distance[1] for c in rows])
    m_lo, m_hi = col([c.mass[0] for c in rows]), col([c.mass[1] for c in rows])
    size = col([c.size for c in rows])
    return _Packages(
        d_lo=d_lo,
        d_span=d_hi - d_lo,
        d_scale=(d_hi - d_lo).clamp_min(1e-6),
        m_lo=m_lo,
        m_hi=m_hi,
        m_span=m_hi - m_lo,
        weighted=col([c.distance_weighting for c in rows]),
        size=size,
        clear=(size + 0.6)[:, None],
        band=col([c.radius_band for c in rows]),
        collab=col([c.kind == "collab" for c in rows]),
        g_effector=g_eff.to(device),
        g_x=g_off[..., 0],
        g_y=g_off[..., 1],
    )


def make_layouts(
    scenario: Scenario, num: int, generator: torch.Generator, device: torch.device | str = "cpu"
) -> Layout:
    """Draw `num` random environments of `scenario` (on the generator's device, then moved)."""
    g, gdev = generator, generator.device
    E, N, W = num, scenario.num_robots, scenario.arena
    base, ranks = _arena_constants(W, gdev)
    slots, extent = _spawn_constants(N, 2 * R_MAX + 0.1, gdev)
    spawn_r = extent + R_MAX

    # Robots: a random assignment of robots to spawn slots.
    perm = torch.rand(E, N, generator=g, device=gdev).argsort(-1)
    start = base + slots[perm]

    # Obstacles: anywhere in the arena, clear of the spawn area.
    O = scenario.obstacle_count
    lo, hi = scenario.obstacle_radius
    o_r = lo + (hi - lo) * torch.rand(E, O, generator=g, device=gdev)
    cand = torch.rand(E, _CANDIDATES, O, 2, generator=g, device=gdev) * W
    dc = (cand - base).norm(dim=-1)
    r4 = o_r.view(E, 1, O, 1)
    margin_ok = ((cand > r4) & (cand < W - r4)).all(-1)
    o_pos = _first_valid(cand, margin_ok & (dc > spawn_r + o_r[:, None] + 0.5), ranks)

    # Packages, class by class.
    Q, G = scenario.num_packages, scenario.max_grips
    try:
        k = _package_constants(scenario.packages, G, gdev)
    except TypeError:  # a package class that cannot be hashed: not cached
        k = _package_constants.__wrapped__(scenario.packages, G, gdev)
    u = torch.rand(E, _CANDIDATES, Q, generator=g, device=gdev)
    # (x * 2) * pi, one product: scaling by 2 is exact
    ang = torch.rand(E, _CANDIDATES, Q, generator=g, device=gdev) * (2 * math.pi)
    dist = k.d_lo + k.d_span * u
    cand = base + dist[..., None] * torch.stack([ang.cos(), ang.sin()], -1)
    ok = ((cand > k.clear) & (cand < W - k.clear)).all(-1)
    if O:
        do = (cand.unsqueeze(3) - o_pos.view(E, 1, 1, O, 2)).norm(dim=-1)  # [E, _CANDIDATES, Q, O]
        ok &= (do > o_r.view(E, 1, 1, O) + k.clear).all(-1)
    p_pos = _first_valid(cand, ok, ranks)
    d0 = (p_pos - base).norm(dim=-1)

    frac = ((d0 - k.d_lo) / k.d_scale).clamp(0, 1)
    mass = torch.where(
        k.weighted,
        k.m_hi - k.m_span * frac,
        k.m_lo + k.m_span * torch.rand(E, Q, generator=g, device=gdev),
    )

    # a random orientation of each package's grip ring
    rot = (torch.rand(E, Q, generator=g, device=gdev) * (2 * math.pi))[..., None]
    cs, sn = rot.cos(), rot.sin()
    g_off = torch.stack([cs * k.g_x - sn * k.g_y, sn * k.g_x + cs * k.g_y], -1)

    seed = torch.randint(0, 2**31 - 1, (E,), generator=g, device=gdev)
    out = Layout(
        p_present=torch.ones(E, Q, dtype=torch.bool, device=gdev),
        p_pos=p_pos,
        p_mass=mass,
        p_band=k.band.repeat(E, 1, 1),
        p_size=k.size.repeat(E, 1),
        p_collab=k.collab.repeat(E, 1),
        g_effector=k.g_effector.repeat(E, 1, 1),
        g_offset=g_off,
        o_pos=o_pos,
        o_radius=o_r,
        o_present=torch.ones(E, O, dtype=torch.bool, device=gdev),
        start=start,
        seed=seed,
    )
    if out.seed.device == torch.device(device):
        return out
    return Layout(*(t.to(device) for t in out))
