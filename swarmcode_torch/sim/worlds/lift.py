"""The simulator's lift rule, searched: what the designs the hardware catalog builds can lift
(`max_lift`, `fewest_designs`), what the cheapest robot that lifts a load costs
(`cheapest_robot`) and how common the designs that lift a class are (`lift_shares`)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import replace
from functools import lru_cache

import torch

from ..hardware import NUM_TIERS, R_MAX, R_MIN, Catalog, default_catalog, phenotype
from ..scenario import EFFECTORS, PackageClass, Scenario
from ..state import WorldParams, capabilities
from .model import _NAMES, OBSTACLE_RADIUS


def _hardware_grid() -> tuple[torch.Tensor, ...]:
    """Every tier combination with the torque operating point at 0 and at 1 and the battery
    point at 0: chassis, battery, motor, torque [K]. These are the designs that lift the most
    at each radius: the lift rule's margin, force - lift_force x (mass + load), is linear in the
    torque point (force and motor mass both are), so one of its ends is the best, and a larger
    battery only adds mass."""
    rows = list(itertools.product(range(NUM_TIERS), range(NUM_TIERS), range(NUM_TIERS)))
    combos = [(c, b, m, u) for c, b, m in rows for u in (0.0, 1.0)]
    t = torch.tensor(combos, dtype=torch.float32, device="cpu")
    return t[:, 0].long(), t[:, 1].long(), t[:, 2].long(), t[:, 3]


def _designs(radii: torch.Tensor, effectors: Sequence[int], catalog: Catalog):
    """The phenotypes of every effector x radius x hardware combination, flattened [D]."""
    ch, ba, mo, tq = _hardware_grid()
    E, R, K = len(effectors), radii.numel(), ch.numel()
    eff = torch.tensor(list(effectors), dtype=torch.long).reshape(E, 1, 1).expand(E, R, K)
    r = radii.reshape(1, R, 1).expand(E, R, K)

    def grid(x: torch.Tensor) -> torch.Tensor:
        return x.reshape(1, 1, K).expand(E, R, K).reshape(-1)

    return phenotype(
        r.reshape(-1),
        grid(ch),
        grid(ba),
        grid(mo),
        grid(tq),
        torch.zeros(E * R * K, dtype=torch.float32),
        eff.reshape(-1),
        catalog,
    )


def _max_load(radii: Sequence[float], catalog: Catalog) -> list[float]:
    """For each radius, the heaviest load any design of that radius lifts by the lift rule
    (payload >= load and force >= lift_force x (robot mass + load))."""
    r = torch.tensor(list(radii), dtype=torch.float32)
    ph = _designs(r, [0], catalog)
    lf = WorldParams().lift_force
    load = torch.minimum(ph.payload, ph.force / lf - ph.mass).reshape(r.numel(), -1)
    return [float(x) for x in load.amax(dim=1)]


@lru_cache(maxsize=4)
def _lift_curve(catalog: Catalog) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Radii from R_MIN to R_MAX every 0.5 mm and the heaviest load a robot of each lifts."""
    radii = tuple(R_MIN + i * (R_MAX - R_MIN) / 700 for i in range(701))
    return radii, tuple(_max_load(radii, catalog))


def max_lift(band: tuple[float, float] = (R_MIN, R_MAX), catalog: Catalog | None = None) -> float:
    """The heaviest load a robot with a radius in a band can lift, with the best hardware.

    Args:
        band: the radius band (m).
        catalog: the hardware catalog (default: the built-in one).

    Returns:
        The load (kg), by the simulator's lift rule; 0 for a band that holds no robot radius.
    """
    cat = catalog or default_catalog()
    a, b = max(band[0], R_MIN), min(band[1], R_MAX)
    if a > b:
        return 0.0
    radii, loads = _lift_curve(cat)
    inside = [x for r, x in zip(radii, loads) if a <= r <= b]
    return max(inside + _max_load([a, b], cat))


def _peak_radius(catalog: Catalog) -> float:
    radii, loads = _lift_curve(catalog)
    return radii[max(range(len(loads)), key=loads.__getitem__)]


def _heaviest(s: Scenario) -> Scenario:
    """`s` with every class's packages at its heaviest mass (`capabilities` reads the lightest)."""
    return replace(s, packages=tuple(replace(c, mass=(c.mass[1], c.mass[1])) for c in s.packages))


def _grid_radii(s: Scenario) -> torch.Tensor:
    """Radii every mm, every band edge, and for every class load and chassis tier the smallest
    radius whose payload carries it."""
    rs = {round(R_MIN + i * 0.001, 6) for i in range(351)}
    cat = s.hardware
    for c in s.packages:
        rs.update(x for x in c.radius_band if R_MIN <= x <= R_MAX)
        for m in c.mass:
            load = m / len(c.grips)
            for strength in cat.chassis_strength:
                if strength > 0:
                    r = math.sqrt(load / (strength * math.pi)) * (1 + 1e-6)
                    if R_MIN <= r <= R_MAX:
                        rs.add(r)
    return torch.tensor(sorted(rs), dtype=torch.float32)


def _tokens(s: Scenario) -> list[tuple[int, int]]:
    """What a team must hold to lift every class: (class, effector) for an individual class's
    effector and for each distinct grip effector of a collaborative one."""
    return [(i, e) for i, c in enumerate(s.packages) for e in sorted(set(c.grips))]


def _coverage(s: Scenario) -> tuple[list[tuple[int, int]], list[int]]:
    """The requirement tokens of `s` and the distinct coverage masks of the designs the catalog
    builds (bit t: the design holds token t, by `capabilities`), only the maximal ones."""
    ph = _designs(_grid_radii(s), sorted(EFFECTORS.values()), s.hardware)
    cap = capabilities(ph, s, WorldParams.for_scenario(s))  # [D, U]
    tokens = _tokens(s)
    mask = torch.zeros(cap.shape[0], dtype=torch.long)
    for t, (i, e) in enumerate(tokens):
        mask |= (cap[:, i] & (ph.effector == e)).long() << t
    masks = [int(m) for m in torch.unique(mask) if int(m)]
    maximal = [m for m in masks if not any(o != m and o & m == m for o in masks)]
    return tokens, sorted(maximal)


def fewest_designs(s: Scenario, heaviest: bool = False) -> int | None:
    """The fewest distinct robot designs that together can lift every package class of a scenario.

    By the simulator's lift rule (`sim.state.capabilities`), searched over the designs the
    scenario's hardware builds (every effector, radii every mm, at every band edge and at every
    payload threshold, every tier, the torque operating point at both ends). A collaborative class
    takes one design per grip effector.

    Args:
        s: the scenario.
        heaviest: judge each class by its heaviest package (default: its lightest, as the lift
            rule reads it).

    Returns:
        The count, or None when some class cannot be lifted at all.
    """
    s = _heaviest(s) if heaviest else s
    tokens, maximal = _coverage(s)
    full = (1 << len(tokens)) - 1
    covered = 0
    for m in maximal:
        covered |= m
    if covered != full:
        return None
    for size in range(1, len(tokens) + 1):
        for combo in itertools.combinations(maximal, size):
            acc = 0
            for m in combo:
                acc |= m
            if acc == full:
                return size
    return None  # pragma: no cover - the whole set covers


def _unliftable(s: Scenario) -> str | None:
    """Words naming a class whose heaviest package no design lifts, else None."""
    tokens, maximal = _coverage(_heaviest(s))
    covered = 0
    for m in maximal:
        covered |= m
    for t, (i, e) in enumerate(tokens):
        if not covered >> t & 1:
            return (
                f"packages[{i}] ({s.packages[i].label}): no {_NAMES[e]} robot the hardware "
                "catalog builds lifts its heaviest package"
            )
    return None


# ------------------------------------------------------------------ costs
def cheapest_robot(
    load: float,
    band: tuple[float, float] = (R_MIN, R_MAX),
    effector: str = "pincher",
    catalog: Catalog | None = None,
) -> float | None:
    """The cost of the cheapest robot with an effector and a radius in a band that lifts a load.

    By the lift rule, checked with `sim.state.capabilities` on its phenotype. Solved per tier
    combination: the smallest radius whose payload carries the load (cost grows with the radius),
    then the lowest torque operating point whose force moves robot and load, the battery at its
    lowest capacity.

    Args:
        load: the load (kg).
        band: the radius band (m).
        effector: "pincher" or "suction".
        catalog: the hardware catalog (default: the built-in one).

    Returns:
        Its cost ($), or None if no such robot lifts the load.
    """
    cat = catalog or default_catalog()
    lf = WorldParams().lift_force
    lo, hi = max(band[0], R_MIN), min(band[1], R_MAX)
    found = []
    for c, m, b in itertools.product(range(NUM_TIERS), repeat=3):
        strength = cat.chassis_strength[c]
        if load > 0 and strength <= 0:
            continue
        carry = math.sqrt(load / (strength * math.pi)) * (1 + 1e-6) if load > 0 else 0.0
        r = max(lo, carry)
        if r > hi:
            continue
        area = math.pi * r * r
        bat = cat.battery_capacity[b] * cat.battery_capacity_floor
        rest = cat.base_mass + cat.effector_mass + cat.chassis_density[c] * area
        rest += bat / cat.battery_density[b]
        F, f, M = cat.motor_force[m], cat.motor_force_floor, cat.motor_mass[m]
        need = lf * (rest + 0.5 * M + load) - F * f
        slope = F * (1 - f) - lf * 0.5 * M
        u = 0.0
        if need > 0:
            if slope <= 0:
                continue
            if need / slope > 1:
                continue
            u = min(need / slope + 1e-5, 1.0)
        found.append((c, m, b, r, u))
    if not found:
        return None
    t = torch.tensor(found, dtype=torch.float32)
    ph = phenotype(
        t[:, 3],
        t[:, 0].long(),
        t[:, 2].long(),
        t[:, 1].long(),
        t[:, 4],
        torch.zeros(len(found)),
        torch.full((len(found),), EFFECTORS[effector], dtype=torch.long),
        cat,
    )
    cls = PackageClass("individual", 1, (1.0, 2.0), (load, load), (EFFECTORS[effector],), band)
    probe = Scenario("probe", "", 20.0, 1.5, 1, 1, 0.0, 0, OBSTACLE_RADIUS, (cls,), cat)
    ok = capabilities(ph, probe, WorldParams())[:, 0]
    costs = [float(x) for x, good in zip(ph.cost, ok) if bool(good)]
    return min(costs) if costs else None


#: Random designs `lift_shares` draws (from a generator of its own: the same shares every call).
SHARE_DESIGNS = 20_000

#: A class whose heaviest package fewer than this share of random designs lift is a needle: in
#: the niche study (experiments/2026-12-05-niche-generalization-v08, "Why five train worlds are
#: never kept") the default never delivered such a class (0.01-0.08 % on the train worlds; every
#: other class at least 8 %), though hand-built robots do.
NEEDLE_SHARE = 0.01


def lift_shares(s: Scenario, designs: int = SHARE_DESIGNS, seed: int = 0) -> list[float]:
    """For each package class of `s`, the share of `designs` random designs (every hardware gene
    uniform: the effector, the radius in [R_MIN, R_MAX], each tier, the torque and battery
    operating points in [0, 1], as a run's first generation draws them) that lift its heaviest
    package (each robot's share of a collaborative one) by the simulator's lift rule."""
    g = torch.Generator().manual_seed(seed)

    def tiers() -> torch.Tensor:
        return torch.randint(0, NUM_TIERS, (designs,), generator=g)

    radius = R_MIN + (R_MAX - R_MIN) * torch.rand(designs, generator=g)
    chassis, battery, motor = tiers(), tiers(), tiers()
    torque, charge = torch.rand(designs, generator=g), torch.rand(designs, generator=g)
    effector = torch.randint(0, len(EFFECTORS), (designs,), generator=g)
    ph = phenotype(radius, chassis, battery, motor, torque, charge, effector, s.hardware)
    lifts = capabilities(ph, _heaviest(s), WorldParams.for_scenario(s))
    return [float(x) for x in lifts.float().mean(0)]


def needles(s: Scenario, least: float = NEEDLE_SHARE) -> list[tuple[int, float]]:
    """(class index, share) of each package class of `s` whose heaviest package fewer than
    `least` of random designs lift (`lift_shares`)."""
    return [(i, share) for i, share in enumerate(lift_shares(s)) if share < least]
