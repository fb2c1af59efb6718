"""Drawing a world: the niches' radius bands and mass ranges, the family's extra class, the
packages' distances, then the checks that the drawn world is solvable with exactly the niches
asked for (`generate_world`)."""

from __future__ import annotations

import math
import random
from collections.abc import Sequence

from ..hardware import R_MAX, R_MIN, Catalog, default_catalog
from ..scenario import PACKAGE_CLEARANCE, Scenario, ScenarioError, scenario_from_dict
from .knobs import _check_knobs
from .lift import _peak_radius, _unliftable, cheapest_robot, fewest_designs, max_lift, needles
from .model import (
    COLLAB_SIZE,
    INDIVIDUAL_SIZE,
    LIFT_MARGIN,
    MAX_DRAWS,
    OBSTACLE_RADIUS,
    Niche,
    World,
    _Redraw,
)
from .reach import REACH_SHARE, out_of_reach


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


def _draw_single(
    rng: random.Random, e: str, knobs: dict, catalog: Catalog
) -> tuple[list[tuple], list[Niche]]:
    """Family "single": 2 or 3 classes of effector `e` whose radius bands all hold one radius
    (the hub) and whose masses its robots lift: one niche."""
    m_lo, m_hi = knobs["mass"]
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
    classes: list[tuple] = []
    for j in range(k):
        lo = _down(R_MIN + (hub - 0.03 - R_MIN) * rng.random(), 2)
        hi = _up(hub + 0.03 + (R_MAX - hub - 0.03) * rng.random(), 2)
        bands.append((max(lo, R_MIN), min(hi, R_MAX)))
        width = min(ceil - m_lo, (0.15 + 0.2 * rng.random()) * (m_hi - m_lo))
        lo_m = m_lo + us[j] * (ceil - m_lo - width)
        note = f"one {e} design of radius {hub:g} m lifts this class and every other"
        classes.append((e, bands[-1], _rounded(lo_m, lo_m + width, m_lo, ceil, 1), note))
    common = (max(b[0] for b in bands), min(b[1] for b in bands))
    return classes, [Niche(e, common, 0)]


def _draw_generalist(rng: random.Random, group: tuple, knobs: dict) -> tuple:
    """The generalist class of family "generalist": a band over two adjacent niches of the
    first effector, lighter than either's packages."""
    m_lo, m_hi = knobs["mass"]
    e, bands, masses = group
    j = int(rng.random() * (len(bands) - 1))
    band = (bands[j][0], bands[j + 1][1])
    ceil = min(masses[j][0], masses[j + 1][0])
    width = min(ceil - m_lo, (0.15 + 0.2 * rng.random()) * (m_hi - m_lo))
    lo = m_lo + rng.random() * (ceil - m_lo - width)
    note = (
        f"generalist: the {e} robots of niches {j + 1} and {j + 2} both lift these "
        "(no niche of its own)"
    )
    return e, band, _rounded(lo, lo + width, m_lo, ceil, 1), note


def _draw_collab(rng: random.Random, groups: list[tuple], knobs: dict) -> tuple:
    """The collaborative class of family "collab": one grip per effector of the niches, light
    enough per grip for their designs."""
    m_lo, m_hi = knobs["mass"]
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
    return grips, (R_MIN, R_MAX), _rounded(lo, lo + width, m_lo, ceil, 1), note


def _draw_niches(
    rng: random.Random, order: list[str], knobs: dict, catalog: Catalog
) -> tuple[list[tuple], list[Niche]]:
    """The families but "single": one exclusive class per niche, the niches shared among the
    effectors in `order`, then the family's extra class."""
    n, family, mode = knobs["niches"], knobs["family"], knobs["bands"]
    classes: list[tuple] = []
    niches: list[Niche] = []
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
        classes.append(_draw_generalist(rng, groups[0], knobs))
    elif family == "collab":
        classes.append(_draw_collab(rng, groups, knobs))
    return classes, niches


def _world_table(
    rng: random.Random, seed: int, knobs: dict, classes: list[tuple], niches: list[Niche]
) -> tuple[dict, str]:
    """The scenario's TOML table (each class's distance drawn) and its description."""
    n, family = knobs["niches"], knobs["family"]
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
    return table, description


def _team_costs(
    scenario: Scenario, niches: list[Niche], knobs: dict, catalog: Catalog
) -> tuple[list[float], float]:
    """$ of each niche's cheapest robot for its heaviest package, and of the cheapest team with
    one robot per niche; _Redraw when a niche has none or the budget does not cover the team."""
    n = knobs["niches"]
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
    return cheapest, team


def _check_niche_count(scenario: Scenario, n: int) -> None:
    """_Redraw unless exactly `n` designs lift every class, by its lightest and its heaviest
    packages."""
    heavy = fewest_designs(scenario, heaviest=True)
    if heavy is None:
        raise _Redraw(_unliftable(scenario) or "a package class no robot lifts")
    light = fewest_designs(scenario)
    if light != n or heavy != n:
        raise _Redraw(
            f"the drawn classes need {light} designs by their lightest packages and {heavy} by "
            f"their heaviest, not {n}"
        )


def _check_lift_shares(scenario: Scenario, least: float) -> None:
    """_Redraw if a class's heaviest package is lifted by fewer than `least` of random designs
    (`needles`; 0: no check)."""
    if least <= 0:
        return
    low = needles(scenario, least)
    if low:
        i, share = low[0]
        raise _Redraw(
            f"class {i + 1} ({scenario.packages[i].label}): {share:.2%} of random designs lift "
            f"its heaviest package, fewer than min_lift_share {least:.2%}"
        )


def _check_reach(scenario: Scenario, niches: list[Niche], least: float) -> None:
    """_Redraw if a niche's exclusive class is out of reach: the best hand swarm of its designs
    delivers fewer than `least` of its packages an episode (`out_of_reach`; 0: no check)."""
    if least <= 0:
        return
    far = out_of_reach(scenario, niches, least)
    if far:
        i, r = far[0]
        raise _Redraw(
            f"niche {i + 1} ({niches[i].label}): a full swarm of its best design brings home "
            f"{r:.0%} of its class's packages an episode, fewer than min_reach {least:.0%}"
        )


def _draw(rng: random.Random, seed: int, knobs: dict, catalog: Catalog) -> World:
    order = list(knobs["effectors"])
    if len(order) > 1 and rng.random() < 0.5:
        order.reverse()
    # (effector, band, mass, note) of each class, the niches' exclusive ones first
    if knobs["family"] == "single":
        classes, niches = _draw_single(rng, order[0], knobs, catalog)
    else:
        classes, niches = _draw_niches(rng, order, knobs, catalog)
    table, description = _world_table(rng, seed, knobs, classes, niches)
    try:
        scenario = scenario_from_dict(table, f"world {table['name']}")
    except ScenarioError as e:
        raise _Redraw(str(e)) from None
    # the cheap checks first: the cost of a team, then the search over designs
    cheapest, team = _team_costs(scenario, niches, knobs, catalog)
    _check_niche_count(scenario, knobs["niches"])
    _check_lift_shares(scenario, knobs["min_lift_share"])
    _check_reach(scenario, niches, knobs["min_reach"])  # the costliest: rollouts
    return World(
        seed=seed,
        knobs=dict(knobs),
        niches=knobs["niches"],
        niche_designs=tuple(niches),
        scenario=scenario,
        table=table,
        notes=tuple(c[3] for c in classes),
        description=description,
        budget=knobs["budget"],
        cheapest=tuple(cheapest),
        min_team_cost=team,
    )


# long: its docstring is the public API's parameter table (the docs' reference); the code is under 80 lines
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
    min_lift_share: float = 0.0,
    min_reach: float = REACH_SHARE,
) -> World:
    """A foraging world drawn from `seed` that needs `niches` distinct robot designs.

    What the knobs mean and how a world is drawn: the module's docstring and docs/WORLDS.md. The
    same seed and knobs give the same world. A draw that is not solvable with exactly `niches`
    designs (a class no robot lifts, packages that cannot be placed, a budget too small) is drawn
    again, up to `MAX_DRAWS` times.

    Args:
        seed: the generator seed.
        niches: how many distinct designs the world needs (1-6).
        effectors: the effectors its niches use (at most 3 niches each).
        bands: "disjoint" or "overlapping" radius bands for the niches of one effector
            (overlapping bands are told apart by mass, so they need a mass range up to ~120 kg).
        mass: the range (kg) the classes' masses are drawn from.
        distance: the range (m from the base centre) the classes' distances are drawn from.
        inversion: heavy packages lie far from the base (default: near it).
        obstacles: how many obstacles.
        num_robots: the swarm size.
        budget: the $ a run's team may cost (a run setting, written in the header of
            `world_toml`); refused when no team of `num_robots` robots with one robot per niche
            fits it. None: no budget.
        family: "classes", "generalist", "collab" or "single" (`FAMILIES`).
        packages: how many packages in all, shared among the classes.
        species_overhead: the scenario's field of that name.
        episode_ticks: the scenario's episode length.
        arena: the arena's side (m).
        base_radius: the base's radius (m).
        name: the scenario's name (default: one made from the seed and knobs).
        min_lift_share: redraw a world in which a class's heaviest package is lifted by fewer
            than this share of random designs (`lift_shares`: a needle that evolution may never
            find, though a design lifts it; docs/WORLDS.md). 0 (the default): no such check.
        min_reach: redraw a world in which a niche's exclusive class is out of reach: a full
            swarm of the niche's best hand design brings home fewer than this share of the
            class's packages an episode (`reach.niche_reach`: a niche the fitness does not ask
            for; docs/WORLDS.md, "Reach"). Default `REACH_SHARE` (0.5); 0: no such check.

    Returns:
        The `World`: its scenario, niches and knobs.

    Raises:
        ScenarioError: (a ValueError) knobs that no draw can satisfy (a mass beyond any robot's
            lift, an effector that does not exist), at once; or, after `MAX_DRAWS` draws, why the
            last one failed.
    """
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
            min_lift_share=min_lift_share,
            min_reach=min_reach,
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
