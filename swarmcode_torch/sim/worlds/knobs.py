"""The generator's knobs, checked and normalised before a draw: a knob that no draw can satisfy
(a mass beyond any robot's lift, an effector that does not exist) is refused at once with a
ScenarioError naming it."""

from __future__ import annotations

import math
from collections.abc import Sequence

from ..hardware import R_MAX, R_MIN, Catalog
from ..scenario import (
    EFFECTORS,
    MAX_ARENA,
    MAX_EPISODE_TICKS,
    MAX_NAME,
    MAX_NUMBER,
    MAX_PACKAGES,
    PACKAGE_CLEARANCE,
    ScenarioError,
)
from ..state import WorldParams
from .lift import cheapest_robot, max_lift
from .model import (
    BAND_MODES,
    COLLAB_SIZE,
    FAMILIES,
    INDIVIDUAL_SIZE,
    LIFT_MARGIN,
    MAX_NICHES,
    MAX_SEED,
    NICHES_PER_EFFECTOR,
)


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


def _check_design(k: dict) -> int:
    """family, bands, niches, effectors and inversion, checked in `k` (effectors made a list);
    the niche count."""
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
    return n


def _check_fields(k: dict, n: int) -> None:
    """The scenario's own fields in `k`, checked and normalised."""
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
    k["min_lift_share"] = _float(k["min_lift_share"], "min_lift_share", 0.0, 0.5)
    k["min_reach"] = _float(k["min_reach"], "min_reach", 0.0, 1.0)
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


def _check_ranges(k: dict, catalog: Catalog) -> None:
    """The mass and distance ranges in `k`, checked against the lift rule and the arena."""
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


def _check_budget(k: dict, n: int, catalog: Catalog) -> None:
    """The budget in `k`: none, or enough for num_robots of the cheapest robot there is."""
    if k["budget"] is None:
        return
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


def _check_knobs(seed, knobs: dict, catalog: Catalog) -> dict:
    """The knobs, checked and normalised (JSON values); ScenarioError names a bad one."""
    _int(seed, "seed", 0, MAX_SEED)
    k = dict(knobs)
    n = _check_design(k)
    _check_fields(k, n)
    _check_ranges(k, catalog)
    _check_budget(k, n, catalog)
    return k
