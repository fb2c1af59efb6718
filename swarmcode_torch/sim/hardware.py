"""Robot phenotype from hardware genes: mass, drive force, payload, battery and cost.

The catalog of tiers is data (``data/hardware.toml``); this module turns genes into the
physical quantities the world needs. Every function is elementwise over any batch shape.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from typing import NamedTuple

import torch

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


@lru_cache(maxsize=1)
def default_catalog() -> Catalog:
    """The built-in catalog, read from ``data/hardware.toml``."""
    text = resources.files("swarmcode_torch").joinpath("data/hardware.toml").read_text()
    d = tomllib.loads(text)
    b, c, m, bat = d["base"], d["chassis"], d["motor"], d["battery"]
    return Catalog(
        base_mass=b["mass"], base_cost=b["cost"], effector_mass=b["effector_mass"],
        effector_cost=b["effector_cost"],
        chassis_density=tuple(c["areal_density"]), chassis_strength=tuple(c["strength"]),
        chassis_cost_per_area=tuple(c["cost_per_area"]),
        motor_force=tuple(m["force"]), motor_force_floor=m["force_floor"],
        motor_efficiency=tuple(m["efficiency"]), motor_mass=tuple(m["mass"]),
        motor_cost=tuple(m["cost"]),
        battery_capacity=tuple(bat["capacity"]), battery_capacity_floor=bat["capacity_floor"],
        battery_density=tuple(bat["energy_density"]),
        battery_cost_per_kj=tuple(bat["cost_per_kj"]),
    )


class Phenotype(NamedTuple):
    """Physical robot properties, each a tensor of the genes' batch shape."""

    radius: torch.Tensor      # m
    mass: torch.Tensor        # kg (empty robot)
    force: torch.Tensor       # N, maximum drive force
    payload: torch.Tensor     # kg the chassis can carry
    capacity: torch.Tensor    # J, full battery
    efficiency: torch.Tensor  # electrical -> mechanical
    effector: torch.Tensor    # long, 0 suction / 1 pincher
    cost: torch.Tensor        # $


def _tier(values: tuple[float, ...], idx: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    table = torch.tensor(values, dtype=like.dtype, device=like.device)
    return table[idx.long()]


def phenotype(radius: torch.Tensor, chassis: torch.Tensor, battery: torch.Tensor,
              motor: torch.Tensor, torque_point: torch.Tensor, battery_point: torch.Tensor,
              effector: torch.Tensor, catalog: Catalog | None = None) -> Phenotype:
    """Phenotype of robots given their hardware genes (tiers as indices 0..2)."""
    cat = catalog or default_catalog()
    r = radius.float()
    area = math.pi * r * r
    u_m = torque_point.float().clamp(0, 1)
    u_b = battery_point.float().clamp(0, 1)

    chassis_mass = _tier(cat.chassis_density, chassis, r) * area
    payload = _tier(cat.chassis_strength, chassis, r) * area
    chassis_cost = _tier(cat.chassis_cost_per_area, chassis, r) * area

    force = _tier(cat.motor_force, motor, r) * (cat.motor_force_floor + (1 - cat.motor_force_floor) * u_m)
    efficiency = _tier(cat.motor_efficiency, motor, r)
    motor_scale = 0.5 + 0.5 * u_m
    motor_mass = _tier(cat.motor_mass, motor, r) * motor_scale
    motor_cost = _tier(cat.motor_cost, motor, r) * motor_scale

    capacity = _tier(cat.battery_capacity, battery, r) * (
        cat.battery_capacity_floor + (1 - cat.battery_capacity_floor) * u_b)
    battery_mass = capacity / _tier(cat.battery_density, battery, r)
    battery_cost = capacity / 1000.0 * _tier(cat.battery_cost_per_kj, battery, r)

    mass = cat.base_mass + cat.effector_mass + chassis_mass + motor_mass + battery_mass
    cost = cat.base_cost + cat.effector_cost + chassis_cost + motor_cost + battery_cost
    return Phenotype(r, mass, force, payload, capacity, efficiency, effector.long(), cost)
