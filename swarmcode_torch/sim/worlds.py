"""Generated worlds: scenarios drawn from a seed and a few knobs, each with the number of niches
it needs known by construction (docs/WORLDS.md).

A *niche* is a robot design a world needs: an (effector, radius band) whose designs alone can
lift one of the world's package classes, its *exclusive* class. The generator draws one
exclusive class per niche so that no design lifts the exclusive classes of two niches (they
differ in effector, in radius band, or, where two bands of one effector overlap, in mass: the
robots in the overlap are too weak for the larger band's packages), and so that the niche's
strongest designs lift its class's heaviest package. Then

    niches = the fewest distinct robot designs that together can lift every package class
             (a collaborative class: every one of its grips),

by the simulator's own lift rule (`sim.state.capabilities`: the effector, the radius band, a
payload and a drive force for the load). `generate_world` checks the count on every world it
returns: it searches the designs the hardware catalog can build (`fewest_designs`), and a world
whose count is not the one asked for, or that some class makes unsolvable, is drawn again.

Everything is drawn from `random.Random(seed)`: the same seed and knobs give the same world
and byte for byte the same TOML (`world_toml`), which `parse_scenario` / `load_scenario` read
back into the same `Scenario`. `split_seeds` and `study_worlds` give fixed, disjoint train and
test sets of worlds.
"""

from __future__ import annotations

import itertools
import json
import math
import random
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache

import torch

from .hardware import NUM_TIERS, R_MAX, R_MIN, Catalog, default_catalog, phenotype
from .scenario import (
    EFFECTORS,
    MAX_ARENA,
    MAX_EPISODE_TICKS,
    MAX_NAME,
    MAX_NUMBER,
    MAX_PACKAGES,
    PACKAGE_CLEARANCE,
    PackageClass,
    Scenario,
    ScenarioError,
    scenario_from_dict,
)
from .state import WorldParams, capabilities

#: The families of worlds (`generate_world(family=...)`):
#: "classes": one exclusive package class per niche;
#: "generalist": plus one class that the designs of two niches of one effector can both lift (a
#: radius band over both of theirs, lighter than either's packages); the niche count is unchanged;
#: "collab": plus one collaborative class, one grip per effector of the niches (two grips of the
#: same effector where the niches have one), light enough per grip for the niches' designs: it
#: needs no design beyond the niches', so the niche count is unchanged;
#: "single": 2 or 3 classes of one effector with different radius bands and masses that one
#: design (a radius inside every band, strong enough for every class) lifts: niches = 1.
FAMILIES = ("classes", "generalist", "collab", "single")
#: "disjoint": the radius bands of one effector's niches do not meet; "overlapping": adjacent
#: bands overlap and the larger band's packages are too heavy for the robots in the overlap.
BAND_MODES = ("disjoint", "overlapping")
MAX_NICHES = 6
#: The most niches one effector holds: radius bands of about a third of [R_MIN, R_MAX] each.
NICHES_PER_EFFECTOR = 3
#: Draws of one seed before `generate_world` gives up on the knobs.
MAX_DRAWS = 64
#: kg kept between a class's mass and what the robots that must (or must not) lift it can lift.
LIFT_MARGIN = 2.0
#: Generator seeds of the two study splits: disjoint, fixed (`split_seeds`).
TRAIN_SEEDS = range(1000, 2000)
TEST_SEEDS = range(5000, 6000)
OBSTACLE_RADIUS = (0.4, 0.8)
INDIVIDUAL_SIZE = 0.2
COLLAB_SIZE = 0.5
MAX_SEED = 2**63 - 1
_NAMES = {v: k for k, v in EFFECTORS.items()}


class _Redraw(Exception):
    """A draw that does not give a solvable world with the niches asked for; why, in words."""


@dataclass(frozen=True)
class Niche:
    """One niche of a generated world: the designs with `effector` and a radius in `band` are
    the ones that lift package class `exclusive` (an index into the scenario's packages)."""

    effector: str
    band: tuple[float, float]
    exclusive: int

    @property
    def label(self) -> str:
        return f"{self.effector}, robots {self.band[0]:g}-{self.band[1]:g} m"


@dataclass(frozen=True)
class World:
    """A generated world: the scenario, the TOML table it is written as, the niches it needs
    and how it was drawn. `world_toml` writes it as a scenario file."""

    seed: int
    #: the knobs it was drawn with (JSON values), `generate_world`'s keywords
    knobs: dict
    #: the fewest distinct robot designs that together lift every package class
    niches: int
    niche_designs: tuple[Niche, ...]
    scenario: Scenario
    #: the scenario as the TOML table of an ordinary scenario file (`scenario_from_dict` of it
    #: gives `scenario`)
    table: dict
    #: a note on each package class (what it is for), written as a comment above it
    notes: tuple[str, ...]
    description: str
    #: the fabrication budget in $ it was drawn for (a run setting, not part of the scenario)
    budget: float | None
    #: $ of the cheapest robot of each niche that lifts the heaviest package of its class
    cheapest: tuple[float, ...]
    #: $: the least a team of num_robots robots with one robot of each niche can cost (the
    #: others at the price of the cheapest robot there is) plus the species overhead per niche
    min_team_cost: float
    #: ("train" | "test", index) for a study world (`study_world`)
    study: tuple[str, int] | None = None


# ------------------------------------------------------------------ the lift rule, searched
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
    """The heaviest load (kg) a robot with a radius in `band` can lift, by the simulator's lift
    rule with the best hardware of `catalog` (the built-in one by default); 0 for a band that
    holds no robot radius."""
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
    """The fewest distinct robot designs that together can lift every package class of `s` (a
    collaborative class: one design per grip effector), by the simulator's lift rule
    (`sim.state.capabilities`, which reads each class's lightest package; `heaviest`: its
    heaviest instead), searched over the designs `s.hardware` builds (every effector, radii every
    mm, at every band edge and at every payload threshold, every tier, the torque operating
    point at both ends). None when some class cannot be lifted at all."""
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
    """$ of the cheapest robot with `effector` and a radius in `band` that lifts `load` kg (by
    the lift rule, checked with `sim.state.capabilities` on its phenotype); None if none does.
    Solved per tier combination: the smallest radius whose payload carries the load (cost grows
    with the radius), then the lowest torque operating point whose force moves robot and load,
    the battery at its lowest capacity."""
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


# ------------------------------------------------------------------ drawing
def _up(x: float, digits: int) -> float:
    return math.ceil(x * 10**digits - 1e-9) / 10**digits


def _down(x: float, digits: int) -> float:
    return math.floor(x * 10**digits + 1e-9) / 10**digits


def _rounded(lo: float, hi: float, floor: float, ceil: float, digits: int) -> tuple[float, float]:
    """[lo, hi] rounded inwards to `digits` decimals when that stays inside [floor, ceil]."""
    a, b = _up(lo, digits), _down(hi, digits)
    if a > b:
        a = b = _up(lo, digits)
    if floor <= a <= b <= ceil:
        return a, b
    return lo, hi


def _split(total: int, parts: int) -> list[int]:
    return [total // parts + (1 if i < total % parts else 0) for i in range(parts)]


def _draw_bands(rng: random.Random, k: int, mode: str, top: float) -> list[tuple[float, float]]:
    """Radius bands of one effector's k niches, smallest first."""
    if k == 1:
        return [(R_MIN, R_MAX)]
    seg = (top - R_MIN) / k
    cuts = [R_MIN + j * seg + 0.4 * seg * (rng.random() - 0.5) for j in range(1, k)]
    out = []
    if mode == "disjoint":
        gap = 0.02 + 0.02 * rng.random()
        for j in range(k):
            lo = R_MIN if j == 0 else _up(cuts[j - 1] + gap / 2, 2)
            hi = R_MAX if j == k - 1 else _down(cuts[j] - gap / 2, 2)
            out.append((lo, hi))
    else:
        ov = 0.015 + 0.015 * rng.random()
        for j in range(k):
            lo = R_MIN if j == 0 else _down(cuts[j - 1] - ov, 2)
            hi = R_MAX if j == k - 1 else _up(cuts[j] + ov, 2)
            out.append((lo, hi))
    return out


def _draw_masses(
    rng: random.Random,
    effector: str,
    bands: list[tuple[float, float]],
    mode: str,
    mass: tuple[float, float],
    catalog: Catalog,
) -> list[tuple[float, float]]:
    """The exclusive class's mass range of each band (heavier for larger bands)."""
    m_lo, m_hi = mass
    us = sorted(rng.random() for _ in bands)
    out = []
    for j, band in enumerate(bands):
        lift = max_lift(band, catalog)
        ceil = min(m_hi, lift - LIFT_MARGIN)
        floor = m_lo
        where = f"the {effector} niche of robots {band[0]:g}-{band[1]:g} m"
        if mode == "overlapping" and j > 0:
            overlap = (band[0], bands[j - 1][1])
            floor = max(floor, max_lift(overlap, catalog) + LIFT_MARGIN)
            if floor > ceil:
                raise _Redraw(
                    f"{where} needs packages heavier than {floor:.1f} kg (what its robots in "
                    f"the overlap {overlap[0]:g}-{overlap[1]:g} m with the next smaller band "
                    f"lift, plus {LIFT_MARGIN:g}) and at most {ceil:.1f} kg (mass high "
                    f"{m_hi:g} kg; its robots lift at most {lift:.1f} kg): raise the mass "
                    "range's high end or use bands='disjoint'"
                )
        if floor > ceil:
            raise _Redraw(
                f"{where}: its robots lift at most {lift:.1f} kg, less {LIFT_MARGIN:g} kg of "
                f"margin, lighter than the mass range's low end {m_lo:g} kg"
            )
        width = min(ceil - floor, (0.15 + 0.2 * rng.random()) * (m_hi - m_lo))
        lo = floor + us[j] * (ceil - floor - width)
        out.append(_rounded(lo, lo + width, floor, ceil, 1))
    return out


def _distance(
    rng: random.Random, m: tuple[float, float], knobs: dict, size: float
) -> tuple[float, float]:
    """A class's distance band: heavy near the base (far with `inversion`), from the mass's
    place in the mass range."""
    (m_lo, m_hi), (d_lo, d_hi) = knobs["mass"], knobs["distance"]
    t = 0.5 if m_hi <= m_lo else min(max(((m[0] + m[1]) / 2 - m_lo) / (m_hi - m_lo), 0.0), 1.0)
    span = d_hi - d_lo
    centre = d_lo + t * span if knobs["inversion"] else d_hi - t * span
    centre += 0.1 * span * (rng.random() - 0.5)
    width = min(span, 1.0 + 1.5 * rng.random())
    lo = min(max(centre - width / 2, d_lo), d_hi - width)
    lo = min(lo, knobs["arena"] / 2 - size - PACKAGE_CLEARANCE)
    return _rounded(lo, lo + width, d_lo, d_hi, 1)


def _class_table(
    effector: str | tuple[str, ...],
    count: int,
    dist: tuple[float, float],
    m: tuple[float, float],
    band: tuple[float, float],
    knobs: dict,
) -> dict:
    collab = isinstance(effector, tuple)
    d: dict = {"kind": "collab" if collab else "individual"}
    if collab:
        d["grips"] = list(effector)
    else:
        d["effector"] = effector
    d.update(
        count=count,
        distance=[dist[0], dist[1]],
        mass=[m[0], m[1]],
        distance_weighting=not knobs["inversion"],
        radius_band=[band[0], band[1]],
        size=COLLAB_SIZE if collab else INDIVIDUAL_SIZE,
    )
    return d


def _draw(rng: random.Random, seed: int, knobs: dict, catalog: Catalog) -> World:
    n, family, mode = knobs["niches"], knobs["family"], knobs["bands"]
    order = list(knobs["effectors"])
    if len(order) > 1 and rng.random() < 0.5:
        order.reverse()
    m_lo, m_hi = knobs["mass"]
    # (effector, band, mass, note) of each class, the niches' exclusive ones first
    classes: list[tuple] = []
    niches: list[Niche] = []
    if family == "single":
        e = order[0]
        hub = round(0.2 + 0.25 * rng.random(), 2)
        lift = max_lift((hub, hub), catalog)
        ceil = min(m_hi, lift - LIFT_MARGIN)
        if m_lo > ceil:
            raise _Redraw(
                f"a {e} robot of radius {hub:g} m lifts at most {lift:.1f} kg, less "
                f"{LIFT_MARGIN:g} kg of margin, lighter than the mass range's low end {m_lo:g} kg"
            )
        k = 3 if rng.random() < 0.5 and knobs["packages"] >= 3 else 2
        us = sorted(rng.random() for _ in range(k))
        bands = []
        for j in range(k):
            lo = _down(R_MIN + (hub - 0.03 - R_MIN) * rng.random(), 2)
            hi = _up(hub + 0.03 + (R_MAX - hub - 0.03) * rng.random(), 2)
            bands.append((max(lo, R_MIN), min(hi, R_MAX)))
            width = min(ceil - m_lo, (0.15 + 0.2 * rng.random()) * (m_hi - m_lo))
            lo_m = m_lo + us[j] * (ceil - m_lo - width)
            note = f"one {e} design of radius {hub:g} m lifts this class and every other"
            classes.append((e, bands[-1], _rounded(lo_m, lo_m + width, m_lo, ceil, 1), note))
        common = (max(b[0] for b in bands), min(b[1] for b in bands))
        niches.append(Niche(e, common, 0))
    else:
        counts = _split(n, len(order))
        if family == "generalist" and counts[0] < 2:
            counts = [n] + [0] * (len(order) - 1)
        top = R_MAX if mode == "disjoint" else _peak_radius(catalog)
        groups = []
        for e, k in zip(order, counts):
            if not k:
                continue
            bands = _draw_bands(rng, k, mode, top)
            masses = _draw_masses(rng, e, bands, mode, knobs["mass"], catalog)
            groups.append((e, bands, masses))
            for band, m in zip(bands, masses):
                niche = Niche(e, band, len(classes))
                note = f"niche {len(niches) + 1}: {niche.label}; only its robots lift these"
                niches.append(niche)
                classes.append((e, band, m, note))
        if family == "generalist":
            e, bands, masses = groups[0]
            j = int(rng.random() * (len(bands) - 1))
            band = (bands[j][0], bands[j + 1][1])
            ceil = min(masses[j][0], masses[j + 1][0])
            width = min(ceil - m_lo, (0.15 + 0.2 * rng.random()) * (m_hi - m_lo))
            lo = m_lo + rng.random() * (ceil - m_lo - width)
            note = (
                f"generalist: the {e} robots of niches {j + 1} and {j + 2} both lift these "
                "(no niche of its own)"
            )
            classes.append((e, band, _rounded(lo, lo + width, m_lo, ceil, 1), note))
        elif family == "collab":
            used = [g[0] for g in groups]
            grips = (used[0], used[1]) if len(used) > 1 else (used[0], used[0])
            share = min(max(m[0] for m in g[2]) for g in groups if g[0] in grips)
            ceil = min(m_hi, 2 * share)
            width = min(ceil - m_lo, (0.15 + 0.2 * rng.random()) * (m_hi - m_lo))
            lo = m_lo + (0.5 + 0.5 * rng.random()) * (ceil - m_lo - width)
            note = (
                f"collaborative: one {grips[0]} and one {grips[1]} robot of the niches carry "
                "each together (no niche of its own)"
            )
            classes.append((grips, (R_MIN, R_MAX), _rounded(lo, lo + width, m_lo, ceil, 1), note))
    counts = _split(knobs["packages"], len(classes))
    tables = []
    for (e, band, m, _), count in zip(classes, counts):
        size = COLLAB_SIZE if isinstance(e, tuple) else INDIVIDUAL_SIZE
        tables.append(_class_table(e, count, _distance(rng, m, knobs, size), m, band, knobs))
    near = "far from" if knobs["inversion"] else "near"
    description = (
        f"generated ({family}, seed {seed}): {n} niche{'s' if n > 1 else ''} "
        f"({'; '.join(x.label for x in niches)}), heavy packages {near} the base"
    )
    name = knobs["name"] or f"world-{family}-{n}n-{seed}"
    table = {
        "name": name,
        "description": description,
        "arena": knobs["arena"],
        "base_radius": knobs["base_radius"],
        "num_robots": knobs["num_robots"],
        "episode_ticks": knobs["episode_ticks"],
        "species_overhead": knobs["species_overhead"],
        "obstacles": {"count": knobs["obstacles"], "radius": list(OBSTACLE_RADIUS)},
        "packages": tables,
    }
    try:
        scenario = scenario_from_dict(table, f"world {name}")
    except ScenarioError as e:
        raise _Redraw(str(e)) from None
    # the cheap checks first: the cost of a team, then the search over designs
    cheapest = []
    for x in niches:
        c = scenario.packages[x.exclusive]
        cost = cheapest_robot(c.mass[1], x.band, x.effector, catalog)
        if cost is None:
            raise _Redraw(
                f"no robot of the niche {x.label} lifts the heaviest package of its class "
                f"({c.mass[1]:g} kg)"
            )
        cheapest.append(cost)
    any_robot = cheapest_robot(0.0, catalog=catalog) or 0.0
    team = sum(cheapest) + (knobs["num_robots"] - n) * any_robot + knobs["species_overhead"] * n
    budget = knobs["budget"]
    if budget is not None and budget < team:
        raise _Redraw(
            f"budget: ${budget:,.2f} cannot field {knobs['num_robots']} robots with one robot "
            f"of each of the {n} niches: the cheapest such team costs ${team:,.2f}"
        )
    heavy = fewest_designs(scenario, heaviest=True)
    if heavy is None:
        raise _Redraw(_unliftable(scenario) or "a package class no robot lifts")
    light = fewest_designs(scenario)
    if light != n or heavy != n:
        raise _Redraw(
            f"the drawn classes need {light} designs by their lightest packages and {heavy} by "
            f"their heaviest, not {n}"
        )
    return World(
        seed=seed,
        knobs=dict(knobs),
        niches=n,
        niche_designs=tuple(niches),
        scenario=scenario,
        table=table,
        notes=tuple(c[3] for c in classes),
        description=description,
        budget=budget,
        cheapest=tuple(cheapest),
        min_team_cost=team,
    )


# ------------------------------------------------------------------ the knobs
def _int(v, name: str, lo: int, hi: int) -> int:
    if not isinstance(v, int) or isinstance(v, bool):
        raise ScenarioError(f"{name}: expected an integer, got {v!r:.60}")
    if not lo <= v <= hi:
        raise ScenarioError(f"{name}: must be in [{lo}, {hi}], got {v}")
    return v


def _float(v, name: str, lo: float, hi: float, lo_open: bool = False) -> float:
    if not isinstance(v, (int, float)) or isinstance(v, bool):
        raise ScenarioError(f"{name}: expected a number, got {v!r:.60}")
    v = float(v)
    if not math.isfinite(v) or v < lo or (lo_open and v == lo) or v > hi:
        raise ScenarioError(f"{name}: must be in {'(' if lo_open else '['}{lo:g}, {hi:g}], got {v}")
    return v


def _pair(v, name: str) -> tuple[float, float]:
    if not isinstance(v, (list, tuple)) or len(v) != 2:
        raise ScenarioError(f"{name}: expected (low, high), got {v!r:.60}")
    a, b = (_float(x, name, 0.0, MAX_NUMBER) for x in v)
    if a > b:
        raise ScenarioError(f"{name}: expected low <= high, got ({a:g}, {b:g})")
    return a, b


def _check_knobs(seed, knobs: dict, catalog: Catalog) -> dict:
    """The knobs, checked and normalised (JSON values); ScenarioError names a bad one."""
    _int(seed, "seed", 0, MAX_SEED)
    k = dict(knobs)
    if k["family"] not in FAMILIES:
        raise ScenarioError(
            f"family: expected one of {', '.join(FAMILIES)}, got {k['family']!r:.60}"
        )
    if k["bands"] not in BAND_MODES:
        raise ScenarioError(
            f"bands: expected one of {', '.join(BAND_MODES)}, got {k['bands']!r:.60}"
        )
    n = _int(k["niches"], "niches", 1, MAX_NICHES)
    effs = k["effectors"]
    if isinstance(effs, str) or not isinstance(effs, Sequence) or not effs:
        raise ScenarioError(f"effectors: expected a list of effector names, got {effs!r:.60}")
    for e in effs:
        if e not in EFFECTORS:
            raise ScenarioError(f"effectors: unknown effector {e!r:.40} (known: pincher, suction)")
    if len(set(effs)) != len(effs):
        raise ScenarioError(f"effectors: {list(effs)} names an effector twice")
    k["effectors"] = list(effs)
    if n > NICHES_PER_EFFECTOR * len(effs):
        raise ScenarioError(
            f"niches: {n} niches need more effectors than {list(effs)}: one effector holds at "
            f"most {NICHES_PER_EFFECTOR} (radius bands of {R_MIN:g}-{R_MAX:g} m)"
        )
    if k["family"] == "single" and n != 1:
        raise ScenarioError(f"niches: family 'single' has 1 niche by definition, got niches={n}")
    if k["family"] == "generalist" and n < 2:
        raise ScenarioError("niches: family 'generalist' needs at least 2 niches, got 1")
    if not isinstance(k["inversion"], bool):
        raise ScenarioError(f"inversion: expected true or false, got {k['inversion']!r:.60}")
    k["arena"] = _float(k["arena"], "arena", 0.0, MAX_ARENA, lo_open=True)
    k["base_radius"] = _float(k["base_radius"], "base_radius", 0.0, k["arena"] / 2, lo_open=True)
    k["num_robots"] = _int(k["num_robots"], "num_robots", 1, MAX_PACKAGES * 100)
    if k["num_robots"] < n:
        raise ScenarioError(
            f"num_robots: {k['num_robots']} robots cannot field one robot of each of {n} niches"
        )
    k["episode_ticks"] = _int(k["episode_ticks"], "episode_ticks", 1, MAX_EPISODE_TICKS)
    k["obstacles"] = _int(k["obstacles"], "obstacles", 0, MAX_PACKAGES)
    k["packages"] = _int(k["packages"], "packages", 1, MAX_PACKAGES)
    classes = 2 if k["family"] == "single" else n + (k["family"] in ("generalist", "collab"))
    if k["packages"] < classes:
        raise ScenarioError(
            f"packages: {k['packages']} packages for {classes} package classes (family "
            f"{k['family']!r}, {n} niche{'s' if n > 1 else ''}); every class needs one"
        )
    k["species_overhead"] = _float(k["species_overhead"], "species_overhead", 0.0, MAX_NUMBER)
    name = k["name"]
    if name is not None and (
        not isinstance(name, str)
        or not name.strip()
        or len(name) > MAX_NAME
        or not name.isprintable()
    ):
        raise ScenarioError(
            f"name: expected 1 to {MAX_NAME} printable characters, got {name!r:.60}"
        )
    m_lo, m_hi = _pair(k["mass"], "mass")
    top = max_lift(catalog=catalog)
    if m_lo > top - LIFT_MARGIN:
        raise ScenarioError(
            f"mass: ({m_lo:g}, {m_hi:g}) kg: no robot the hardware catalog builds lifts more "
            f"than {top:.1f} kg (the simulator's lift rule: payload >= load and drive force >= "
            f"{WorldParams().lift_force:g} N/kg x (robot + load)), and the generator keeps "
            f"{LIFT_MARGIN:g} kg of margin"
        )
    if m_hi <= 0:
        raise ScenarioError(f"mass: expected a positive high end, got ({m_lo:g}, {m_hi:g})")
    k["mass"] = [m_lo, m_hi]
    d_lo, d_hi = _pair(k["distance"], "distance")
    size = COLLAB_SIZE if k["family"] == "collab" else INDIVIDUAL_SIZE
    reach = k["arena"] / 2 - size - PACKAGE_CLEARANCE
    if d_lo < k["base_radius"] + size or d_lo > reach or d_hi > reach * math.sqrt(2):
        raise ScenarioError(
            f"distance: ({d_lo:g}, {d_hi:g}) m: packages are placed from base_radius + size "
            f"({k['base_radius'] + size:g} m) out to {reach:g} m (arena/2 - size - "
            f"{PACKAGE_CLEARANCE:g}) from the base centre"
        )
    if d_hi - d_lo < 0.5:
        raise ScenarioError(f"distance: ({d_lo:g}, {d_hi:g}) m: give a range of at least 0.5 m")
    k["distance"] = [d_lo, d_hi]
    if k["budget"] is not None:
        k["budget"] = _float(k["budget"], "budget", 0.0, MAX_NUMBER, lo_open=True)
        floor = k["num_robots"] * (cheapest_robot(0.0, catalog=catalog) or 0.0)
        floor += k["species_overhead"] * n
        if k["budget"] < floor:
            raise ScenarioError(
                f"budget: ${k['budget']:,.2f} cannot field {k['num_robots']} robots of {n} "
                f"species: the cheapest robot there is costs "
                f"${cheapest_robot(0.0, catalog=catalog):,.2f}, so the least such a team "
                f"costs ${floor:,.2f}"
            )
    return k


def generate_world(
    seed: int,
    *,
    niches: int = 3,
    effectors: Sequence[str] = ("pincher", "suction"),
    bands: str = "disjoint",
    mass: tuple[float, float] = (2.0, 24.0),
    distance: tuple[float, float] = (3.0, 9.5),
    inversion: bool = False,
    obstacles: int = 4,
    num_robots: int = 20,
    budget: float | None = None,
    family: str = "classes",
    packages: int = 16,
    species_overhead: float = 0.0,
    episode_ticks: int = 200,
    arena: float = 20.0,
    base_radius: float = 1.5,
    name: str | None = None,
) -> World:
    """A foraging world drawn from `seed` that needs `niches` (1-6) distinct robot designs (the
    module's docstring; docs/WORLDS.md).

    `effectors`: the effectors its niches use (at most 3 niches each); `bands`: "disjoint" or
    "overlapping" radius bands for the niches of one effector (overlapping bands are told apart
    by mass, so they need a mass range up to ~120 kg); `mass`, `distance`: the ranges (kg, m
    from the base centre) the classes' masses and distances are drawn from; heavy packages lie
    near the base, or far from it with `inversion`; `obstacles`: their count; `packages`: how
    many packages in all, shared among the classes; `family`: "classes", "generalist",
    "collab" or "single" (`FAMILIES`); `budget`: the $ a run's team may cost (a run setting,
    written in the header of `world_toml`): refused when no team of num_robots robots with one
    robot per niche fits it. The other knobs are the scenario's fields.

    The same seed and knobs give the same world. A draw that is not solvable with exactly
    `niches` designs (a class no robot lifts, packages that cannot be placed, a budget too
    small) is drawn again, up to `MAX_DRAWS` times; then ScenarioError (a ValueError) says why
    the last draw failed. Knobs that no draw can satisfy (a mass beyond any robot's lift, an
    effector that does not exist) are refused at once."""
    catalog = default_catalog()
    knobs = _check_knobs(
        seed,
        dict(
            niches=niches,
            effectors=effectors,
            bands=bands,
            mass=mass,
            distance=distance,
            inversion=inversion,
            obstacles=obstacles,
            num_robots=num_robots,
            budget=budget,
            family=family,
            packages=packages,
            species_overhead=species_overhead,
            episode_ticks=episode_ticks,
            arena=arena,
            base_radius=base_radius,
            name=name,
        ),
        catalog,
    )
    rng = random.Random(seed)
    reason = ""
    for _ in range(MAX_DRAWS):
        try:
            return _draw(rng, seed, knobs, catalog)
        except _Redraw as e:
            reason = str(e)
    raise ScenarioError(
        f"world: no solvable world with {niches} niche{'s' if niches > 1 else ''} in "
        f"{MAX_DRAWS} draws of seed {seed} with these knobs; the last draw: {reason}"
    )


# ------------------------------------------------------------------ the TOML file
def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    raise TypeError(f"no TOML value for {v!r}")  # pragma: no cover


def _num(x: float) -> str:
    """A number as short as it can be written and read back the same."""
    short = f"{x:g}"
    return short if float(short) == x else repr(x)


def world_command(world: World) -> str:
    """The `swarmcode-torch world` command line that writes `world` again."""
    k = world.knobs
    if world.study is not None:
        return f"swarmcode-torch world --split {world.study[0]} --index {world.study[1]}"
    parts = [
        f"--seed {world.seed}",
        f"--niches {k['niches']}",
        f"--family {k['family']}",
        f"--effectors {','.join(k['effectors'])}",
        f"--bands {k['bands']}",
        f"--mass {_num(k['mass'][0])},{_num(k['mass'][1])}",
        f"--distance {_num(k['distance'][0])},{_num(k['distance'][1])}",
        "--inversion" if k["inversion"] else "--no-inversion",
        f"--obstacles {k['obstacles']}",
        f"--num-robots {k['num_robots']}",
        f"--packages {k['packages']}",
        f"--species-overhead {_num(k['species_overhead'])}",
        f"--episode-ticks {k['episode_ticks']}",
        f"--arena {_num(k['arena'])}",
        f"--base-radius {_num(k['base_radius'])}",
    ]
    if k["budget"] is not None:
        parts.append(f"--budget {_num(k['budget'])}")
    if k["name"] is not None:
        parts.append(f"--name {json.dumps(k['name'])}")
    return "swarmcode-torch world " + " ".join(parts)


def world_toml(world: World) -> str:
    """`world` as a scenario TOML file: a header of comments (the generator, its seed and knobs,
    the niche count and what it means, the budget), then the scenario's fields, each package
    class under a comment saying what it is for. `parse_scenario` reads it back into
    `world.scenario`."""
    knobs = {"seed": world.seed, **world.knobs}
    if world.study is not None:
        knobs["study"] = list(world.study)
    budget = (
        "none (no budget penalty)"
        if world.budget is None
        else f"{world.budget:g} (a run setting, not part of the scenario: evolve --budget "
        f"{world.budget:g})"
    )
    header = [
        "Generated by swarmcode_torch.sim.worlds.generate_world (docs/WORLDS.md).",
        f"reproduce: {world_command(world)}",
        f"knobs: {json.dumps(knobs, sort_keys=True)}",
        f"niches = {world.niches}: the fewest distinct robot designs that together lift every",
        "  package class (a collaborative one: every grip), by the simulator's lift rule;",
        "  each niche has a class that only its designs lift.",
        *(f"  niche {i + 1}: {x.label}" for i, x in enumerate(world.niche_designs)),
        f"budget = {budget}; a team of {world.scenario.num_robots} robots with one robot per "
        f"niche costs at least ${world.min_team_cost:,.2f}",
    ]
    lines = [f"# {h}" for h in header]
    t = world.table
    for key in (
        "name",
        "description",
        "arena",
        "base_radius",
        "num_robots",
        "episode_ticks",
        "species_overhead",
    ):
        lines.append(f"{key} = {_toml(t[key])}")
    lines += ["", "[obstacles]"]
    lines += [f"{key} = {_toml(v)}" for key, v in t["obstacles"].items()]
    for note, p in zip(world.notes, t["packages"]):
        lines += ["", f"# {note}", "[[packages]]"]
        lines += [f"{key} = {_toml(v)}" for key, v in p.items()]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------ study splits
#: The standard study worlds: the knobs of world K of either split (its seed is the split's
#: K-th, `split_seeds`). Three of each niche count 1-5, across the families, inversions and
#: overlapping bands; the same knobs in both splits, so that train and test differ by seed only.
STUDY_SPECS: tuple[dict, ...] = (
    dict(niches=1, family="classes", effectors=("pincher",)),
    dict(niches=1, family="single", effectors=("suction",)),
    dict(niches=1, family="collab", effectors=("pincher",), inversion=True),
    dict(niches=2, family="classes"),
    dict(niches=2, family="classes", effectors=("suction",), inversion=True),
    dict(niches=2, family="generalist", effectors=("pincher",)),
    dict(niches=3, family="classes"),
    dict(niches=3, family="classes", bands="overlapping", mass=(2.0, 120.0)),
    dict(niches=3, family="collab", inversion=True),
    dict(niches=4, family="classes"),
    dict(niches=4, family="generalist", inversion=True),
    dict(niches=4, family="classes", bands="overlapping", mass=(2.0, 120.0)),
    dict(niches=5, family="classes"),
    dict(niches=5, family="collab", inversion=True),
    dict(niches=5, family="generalist", bands="overlapping", mass=(2.0, 120.0)),
)
SPLITS = ("train", "test")


def split_seeds(split: str) -> range:
    """The generator seeds of a study split: "train" 1000-1999, "test" 5000-5999 (disjoint)."""
    if split == "train":
        return TRAIN_SEEDS
    if split == "test":
        return TEST_SEEDS
    raise ScenarioError(f"split: expected 'train' or 'test', got {split!r:.60}")


def study_world(split: str, index: int) -> World:
    """Standard study world `index` (0 .. len(STUDY_SPECS) - 1) of `split`: `generate_world` of
    the split's index-th seed with the knobs `STUDY_SPECS[index]`, named study-SPLIT-INDEX."""
    seeds = split_seeds(split)
    if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(STUDY_SPECS):
        raise ScenarioError(
            f"index: expected an integer in [0, {len(STUDY_SPECS) - 1}], got {index!r:.60}"
        )
    spec = STUDY_SPECS[index]
    world = generate_world(seeds[index], name=f"study-{split}-{index:02d}", **spec)
    return replace(world, study=(split, index))


def study_worlds(split: str) -> list[World]:
    """The standard study worlds of `split` ("train" or "test"), `study_world` of each index:
    15 worlds, three of each niche count 1-5."""
    return [study_world(split, i) for i in range(len(STUDY_SPECS))]
