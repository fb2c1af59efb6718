"""Robot phenotype from hardware genes: mass, drive force, payload, battery and cost.

The catalog of tiers is data (``data/hardware.toml``, or a scenario's own file); this module
reads and checks it and turns genes into the physical quantities the world needs. Every
function is elementwise over any batch shape.
"""

from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from typing import NamedTuple

import torch

from .tensors import cast

# Radius bounds of a robot chassis, in metres (the paper's R_min, R_max).
R_MIN = 0.15
R_MAX = 0.5
NUM_TIERS = 3
SUCTION = 0
PINCHER = 1

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


@dataclass(frozen=True)
class Catalog:
    """Per-tier hardware figures (tuples of 3, tier 1 first)."""

    base_mass: float
    base_cost: float
    effector_mass: float
    effector_cost: float
    chassis_density: tuple[float, ...]
    chassis_strength: tuple[float, ...]
    chassis_cost_per_area: tuple[float, ...]
    motor_force: tuple[float, ...]
    motor_force_floor: float
    motor_efficiency: tuple[float, ...]
    motor_mass: tuple[float, ...]
    motor_cost: tuple[float, ...]
    battery_capacity: tuple[float, ...]
    battery_capacity_floor: float
    battery_density: tuple[float, ...]
    battery_cost_per_kj: tuple[float, ...]


class CatalogError(ValueError):
    """A hardware catalog that cannot be used; the message names the bad field."""


#: The catalog's fields: TOML section, key, Catalog field, per tier (3 values) or one value,
#: and the range each value must lie in (low, high, whether low itself is allowed).
_POSITIVE = (0.0, 1e15, False)
_NONNEGATIVE = (0.0, 1e15, True)
_FRACTION = (0.0, 1.0, True)
_CATALOG_FIELDS = (
    ("base", "mass", "base_mass", False, _POSITIVE),
    ("base", "cost", "base_cost", False, _NONNEGATIVE),
    ("base", "effector_mass", "effector_mass", False, _NONNEGATIVE),
    ("base", "effector_cost", "effector_cost", False, _NONNEGATIVE),
    ("chassis", "areal_density", "chassis_density", True, _NONNEGATIVE),
    ("chassis", "strength", "chassis_strength", True, _NONNEGATIVE),
    ("chassis", "cost_per_area", "chassis_cost_per_area", True, _NONNEGATIVE),
    ("motor", "force", "motor_force", True, _NONNEGATIVE),
    ("motor", "force_floor", "motor_force_floor", False, _FRACTION),
    ("motor", "efficiency", "motor_efficiency", True, (0.0, 1.0, False)),
    ("motor", "mass", "motor_mass", True, _NONNEGATIVE),
    ("motor", "cost", "motor_cost", True, _NONNEGATIVE),
    ("battery", "capacity", "battery_capacity", True, _POSITIVE),
    ("battery", "capacity_floor", "battery_capacity_floor", False, _FRACTION),
    ("battery", "energy_density", "battery_density", True, _POSITIVE),
    ("battery", "cost_per_kj", "battery_cost_per_kj", True, _NONNEGATIVE),
)
CATALOG_SECTIONS = ("base", "chassis", "motor", "battery")


def _catalog_value(v, where: str, per_tier: bool, bounds: tuple[float, float, bool]):
    lo, hi, lo_ok = bounds
    want = f"a list of {NUM_TIERS} numbers (tiers 1, 2, 3)" if per_tier else "a number"
    items = v if per_tier and isinstance(v, list) else [v]
    if (
        per_tier
        and (not isinstance(v, list) or len(v) != NUM_TIERS)
        or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in items)
    ):
        raise CatalogError(f"{where}: expected {want}, got {v!r}")
    for x in items:
        if not (math.isfinite(x) and (lo < x or lo_ok and x == lo) and x <= hi):
            raise CatalogError(
                f"{where}: expected {'' if per_tier else 'a value '}in "
                f"{'[' if lo_ok else '('}{lo:g}, {hi:g}], got {v!r}"
            )
    return tuple(float(x) for x in items) if per_tier else float(v)


def catalog_from_dict(d, source: str = "hardware catalog") -> Catalog:
    """A Catalog from the tables of a hardware TOML file ([base], [chassis], [motor],
    [battery], as in data/hardware.toml); CatalogError naming `source` and the field for a
    missing, unknown or out-of-range one."""
    if not isinstance(d, dict):
        raise CatalogError(f"{source}: expected a table")
    for section in d:
        if section not in CATALOG_SECTIONS:
            raise CatalogError(
                f"{source}: {section}: unknown section (known: {', '.join(CATALOG_SECTIONS)})"
            )
    values = {}
    for section in CATALOG_SECTIONS:
        table = d.get(section)
        if not isinstance(table, dict):
            raise CatalogError(
                f"{source}: [{section}]: {'missing' if table is None else 'expected a table'}"
            )
        keys = [k for s, k, *_ in _CATALOG_FIELDS if s == section]
        for k in table:
            if k not in keys:
                raise CatalogError(
                    f"{source}: {section}.{k}: unknown field (known: {', '.join(keys)})"
                )
    for section, key, name, per_tier, bounds in _CATALOG_FIELDS:
        if key not in d[section]:
            raise CatalogError(f"{source}: {section}.{key}: missing")
        values[name] = _catalog_value(
            d[section][key], f"{source}: {section}.{key}", per_tier, bounds
        )
    return Catalog(**values)


def parse_catalog(data: bytes, source: str) -> Catalog:
    """A Catalog from the bytes of a hardware TOML file (CatalogError naming `source`)."""
    try:
        text = data.decode("utf-8-sig")
        if nesting_depth(text) > MAX_NESTING:
            raise CatalogError(
                f"{source}: nested {nesting_depth(text)} levels deep (at most {MAX_NESTING})"
            )
        d = tomllib.loads(text)
    except UnicodeDecodeError as e:
        raise CatalogError(
            f"{source}: not UTF-8 text (byte 0x{data[e.start]:02x} at offset {e.start})"
        ) from None
    except tomllib.TOMLDecodeError as e:
        raise CatalogError(f"{source}: not valid TOML ({e})") from None
    except RecursionError:
        raise CatalogError(f"{source}: nested too deeply") from None
    return catalog_from_dict(d, source)


#: The deepest nesting of tables and lists accepted in a TOML or JSON file of a scenario or a
#: run (real ones nest 4 deep): deeper input is refused before a parser recurses into it.
MAX_NESTING = 64


def nesting_depth(text: str) -> int:
    """An upper bound of how deep tables and lists nest in TOML or JSON text: the most brackets
    and braces open at once, counted without parsing (brackets inside strings and dotted keys'
    tables are not told apart, so the bound is never too low for a parser's recursion)."""
    if text.count("[") + text.count("{") <= MAX_NESTING:
        return text.count("[") + text.count("{")
    depth = most = 0
    for ch in re.findall(r"[\[\]{}]", text):
        if ch in "[{":
            depth += 1
            if depth > most:
                most = depth
        else:
            depth = max(0, depth - 1)
    return most


def catalog_tables(cat: Catalog) -> dict[str, dict]:
    """The TOML tables of a catalog ({"base": {...}, ...}): `catalog_from_dict` of them gives
    `cat` back."""
    out: dict[str, dict] = {s: {} for s in CATALOG_SECTIONS}
    for section, key, name, per_tier, _ in _CATALOG_FIELDS:
        v = getattr(cat, name)
        out[section][key] = list(v) if per_tier else v
    return out


def catalog_toml_lines(cat: Catalog, prefix: str = "") -> list[str]:
    """The TOML lines of a catalog's tables ([base], ... or, with `prefix` "hardware.",
    [hardware.base], ... for a scenario's inline catalog), written by tomli-w; they parse back
    to `cat`."""
    import tomli_w

    tables: dict = {
        s: {k: [float(x) for x in v] if isinstance(v, list) else float(v) for k, v in t.items()}
        for s, t in catalog_tables(cat).items()
    }
    for part in reversed([p for p in prefix.split(".") if p]):
        tables = {part: tables}
    return [""] + tomli_w.dumps(tables).splitlines()


def default_catalog_bytes() -> bytes:
    """The installed catalog file, ``data/hardware.toml``, as read."""
    return resources.files("swarmcode_torch").joinpath("data/hardware.toml").read_bytes()


@lru_cache(maxsize=1)
def default_catalog() -> Catalog:
    """The built-in catalog, read from ``data/hardware.toml``."""
    return parse_catalog(default_catalog_bytes(), "swarmcode_torch/data/hardware.toml")


class Phenotype(NamedTuple):
    """Physical robot properties, each a tensor of the genes' batch shape."""

    radius: torch.Tensor  # m
    mass: torch.Tensor  # kg (empty robot)
    force: torch.Tensor  # N, maximum drive force
    payload: torch.Tensor  # kg the chassis can carry
    capacity: torch.Tensor  # J, full battery
    efficiency: torch.Tensor  # electrical -> mechanical
    effector: torch.Tensor  # long, 0 suction / 1 pincher
    cost: torch.Tensor  # $


@lru_cache(maxsize=16)
def _tier_tables(
    cat: Catalog, dtype: torch.dtype, device: torch.device
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The catalog's per-tier figures as [figures, NUM_TIERS] tables of one part each (built
    once per catalog, dtype and device, never written to): chassis (areal density, strength,
    cost per area), motor (force, efficiency, mass, cost), battery (capacity, energy density,
    cost per kJ)."""

    def table(*rows: tuple[float, ...]) -> torch.Tensor:
        return torch.tensor(rows, dtype=dtype, device=device)

    return (
        table(cat.chassis_density, cat.chassis_strength, cat.chassis_cost_per_area),
        table(cat.motor_force, cat.motor_efficiency, cat.motor_mass, cat.motor_cost),
        table(cat.battery_capacity, cat.battery_density, cat.battery_cost_per_kj),
    )


def phenotype(
    radius: torch.Tensor,
    chassis: torch.Tensor,
    battery: torch.Tensor,
    motor: torch.Tensor,
    torque_point: torch.Tensor,
    battery_point: torch.Tensor,
    effector: torch.Tensor,
    catalog: Catalog | None = None,
) -> Phenotype:
    """Phenotype of robots given their hardware genes (tiers as indices 0..2)."""
    cat = catalog or default_catalog()
    r = cast(radius, torch.float)
    area = math.pi * r * r
    u_m = cast(torque_point, torch.float).clamp(0, 1)
    u_b = cast(battery_point, torch.float).clamp(0, 1)
    try:
        chassis_t, motor_t, battery_t = _tier_tables(cat, r.dtype, r.device)
    except TypeError:  # a catalog that cannot be hashed: not cached
        chassis_t, motor_t, battery_t = _tier_tables.__wrapped__(cat, r.dtype, r.device)
    # each part's figures at each robot's tier, one gather a part
    motor_force, efficiency, motor_kg, motor_usd = motor_t[:, cast(motor, torch.long)].unbind()
    capacity_t, energy_density, kj_cost = battery_t[:, cast(battery, torch.long)].unbind()
    # the chassis' areal figures (density, strength, cost per area) times the area
    chassis_mass, payload, chassis_cost = (chassis_t[:, cast(chassis, torch.long)] * area).unbind()

    force = motor_force * (cat.motor_force_floor + (1 - cat.motor_force_floor) * u_m)
    motor_scale = 0.5 + 0.5 * u_m
    motor_mass = motor_kg * motor_scale
    motor_cost = motor_usd * motor_scale

    capacity = capacity_t * (cat.battery_capacity_floor + (1 - cat.battery_capacity_floor) * u_b)
    battery_mass = capacity / energy_density
    battery_cost = capacity / 1000.0 * kj_cost

    mass = cat.base_mass + cat.effector_mass + chassis_mass + motor_mass + battery_mass
    cost = cat.base_cost + cat.effector_cost + chassis_cost + motor_cost + battery_cost
    return Phenotype(
        r, mass, force, payload, capacity, efficiency, cast(effector, torch.long), cost
    )
