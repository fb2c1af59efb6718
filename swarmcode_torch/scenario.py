"""Scenarios: the foraging worlds of the paper as data, loadable by name or from a TOML file."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

EFFECTORS = {"suction": 0, "pincher": 1}
MAX_GRIPS = 3


class ScenarioError(ValueError):
    """A scenario that cannot be loaded; the message names the bad field."""


@dataclass(frozen=True)
class PackageClass:
    """A group of packages that share a spec; `count` of them are placed in every environment."""

    kind: str                      # "individual" or "collab"
    count: int
    distance: tuple[float, float]  # from the base centre (m)
    mass: tuple[float, float]      # kg; heavier near the base when distance_weighting
    grips: tuple[int, ...]         # effector of each grip point (one for an individual package)
    radius_band: tuple[float, float] = (0.0, 10.0)  # robot radii that can lift it (m)
    distance_weighting: bool = False
    size: float = 0.2              # package radius (m); grip points lie just outside it

    @property
    def label(self) -> str:
        """e.g. 'pincher 16-24 kg, r 0.32-0.5 m' or 'collab suction+pincher 30-40 kg'."""
        names = {v: k for k, v in EFFECTORS.items()}
        eff = "+".join(names[e] for e in self.grips)
        text = f"{'collab ' if self.kind == 'collab' else ''}{eff} {self.mass[0]:g}-{self.mass[1]:g} kg"
        if self.radius_band != (0.0, 10.0):
            text += f", r {self.radius_band[0]:g}-{self.radius_band[1]:g} m"
        return text


@dataclass(frozen=True)
class Scenario:
    """A foraging world: arena, base, obstacles, packages and swarm size."""

    name: str
    description: str
    arena: float                   # side of the square arena (m); the base is at its centre
    base_radius: float
    num_robots: int
    episode_ticks: int
    species_overhead: float        # $ fabrication overhead per distinct species in a team
    obstacle_count: int
    obstacle_radius: tuple[float, float]
    packages: tuple[PackageClass, ...]

    @property
    def num_packages(self) -> int:
        return sum(p.count for p in self.packages)

    @property
    def max_grips(self) -> int:
        return max((len(p.grips) for p in self.packages), default=1)


def _get(d: dict, key: str, where: str, kind, default=None, required: bool = True):
    if key not in d:
        if required and default is None:
            raise ScenarioError(f"{where}{key}: missing")
        return default
    v = d[key]
    if kind is float and isinstance(v, int) and not isinstance(v, bool):
        v = float(v)
    if not isinstance(v, kind) or isinstance(v, bool) and kind is not bool:
        raise ScenarioError(f"{where}{key}: expected {kind.__name__}, got {v!r}")
    return v


def _range(d: dict, key: str, where: str, default=None, lo: float = 0.0) -> tuple[float, float]:
    v = d.get(key, default)
    if v is None:
        raise ScenarioError(f"{where}{key}: missing")
    if (not isinstance(v, (list, tuple)) or len(v) != 2
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
        raise ScenarioError(f"{where}{key}: expected [low, high], got {v!r}")
    a, b = float(v[0]), float(v[1])
    if a < lo or b < a:
        raise ScenarioError(f"{where}{key}: expected {lo} <= low <= high, got {v!r}")
    return a, b


def _effector(name, where: str) -> int:
    if name not in EFFECTORS:
        raise ScenarioError(f"{where}: unknown effector {name!r} (known: suction, pincher)")
    return EFFECTORS[name]


def scenario_from_dict(d: dict, source: str = "scenario") -> Scenario:
    """Build and validate a :class:`Scenario` from a parsed TOML table."""
    if not isinstance(d, dict):
        raise ScenarioError(f"{source}: expected a table")
    known = {"name", "description", "arena", "base_radius", "num_robots", "episode_ticks",
             "species_overhead", "obstacles", "packages"}
    for k in d:
        if k not in known:
            raise ScenarioError(f"{k}: unknown field (known: {', '.join(sorted(known))})")
    name = _get(d, "name", "", str)
    arena = _get(d, "arena", "", float)
    base_radius = _get(d, "base_radius", "", float)
    num_robots = _get(d, "num_robots", "", int)
    ticks = _get(d, "episode_ticks", "", int)
    overhead = _get(d, "species_overhead", "", float, default=0.0, required=False)
    if arena <= 0:
        raise ScenarioError(f"arena: must be > 0, got {arena}")
    if not 0 < base_radius < arena / 2:
        raise ScenarioError(f"base_radius: must be in (0, arena/2), got {base_radius}")
    if num_robots < 1:
        raise ScenarioError(f"num_robots: must be >= 1, got {num_robots}")
    if ticks < 1:
        raise ScenarioError(f"episode_ticks: must be >= 1, got {ticks}")
    if overhead < 0:
        raise ScenarioError(f"species_overhead: must be >= 0, got {overhead}")

    obs = d.get("obstacles", {})
    if not isinstance(obs, dict):
        raise ScenarioError("obstacles: expected a table")
    obs_count = _get(obs, "count", "obstacles.", int, default=0, required=False)
    if obs_count < 0:
        raise ScenarioError(f"obstacles.count: must be >= 0, got {obs_count}")
    obs_radius = _range(obs, "radius", "obstacles.", default=(0.5, 1.0))

    pkgs = d.get("packages")
    if not isinstance(pkgs, list) or not pkgs:
        raise ScenarioError("packages: expected at least one [[packages]] table")
    classes = []
    for i, p in enumerate(pkgs):
        w = f"packages[{i}]."
        if not isinstance(p, dict):
            raise ScenarioError(f"packages[{i}]: expected a table")
        kind = _get(p, "kind", w, str)
        if kind not in ("individual", "collab"):
            raise ScenarioError(f"{w}kind: expected 'individual' or 'collab', got {kind!r}")
        count = _get(p, "count", w, int)
        if count < 0:
            raise ScenarioError(f"{w}count: must be >= 0, got {count}")
        dist = _range(p, "distance", w)
        if dist[1] > arena / 2 * 1.4142:
            raise ScenarioError(f"{w}distance: {dist[1]} lies outside the arena")
        mass = _range(p, "mass", w)
        if kind == "individual":
            grips = (_effector(_get(p, "effector", w, str), f"{w}effector"),)
            band = _range(p, "radius_band", w, default=(0.0, 10.0))
            size = _get(p, "size", w, float, default=0.2, required=False)
        else:
            g = p.get("grips")
            if not isinstance(g, list) or not 2 <= len(g) <= MAX_GRIPS:
                raise ScenarioError(f"{w}grips: expected a list of 2..{MAX_GRIPS} effectors")
            grips = tuple(_effector(x, f"{w}grips") for x in g)
            band = _range(p, "radius_band", w, default=(0.0, 10.0))
            size = _get(p, "size", w, float, default=0.5, required=False)
        if size <= 0:
            raise ScenarioError(f"{w}size: must be > 0, got {size}")
        dw = _get(p, "distance_weighting", w, bool, default=False, required=False)
        for k in p:
            if k not in {"kind", "count", "distance", "mass", "effector", "grips", "radius_band",
                         "size", "distance_weighting"}:
                raise ScenarioError(f"{w}{k}: unknown field")
        classes.append(PackageClass(kind, count, dist, mass, grips, band, dw, size))
    if sum(c.count for c in classes) < 1:
        raise ScenarioError("packages: the scenario places no package")
    return Scenario(name, str(d.get("description", "")), arena, base_radius, num_robots, ticks,
                    overhead, obs_count, obs_radius, tuple(classes))


def builtin_names() -> list[str]:
    """Names of the built-in scenarios."""
    files = resources.files("swarmcode_torch").joinpath("scenarios").iterdir()
    return sorted(f.name[:-5] for f in files if f.name.endswith(".toml"))


def _parse(text: str, source: str) -> Scenario:
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{source}: not valid TOML ({e})") from None
    return scenario_from_dict(d, source)


def load_scenario(name_or_path: str) -> Scenario:
    """A built-in scenario by name, or a scenario TOML file by path."""
    if name_or_path in builtin_names():
        text = resources.files("swarmcode_torch").joinpath(f"scenarios/{name_or_path}.toml").read_text()
        return _parse(text, name_or_path)
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise ScenarioError(f"scenario file not found: {path}")
        return _parse(path.read_text(), str(path))
    raise ScenarioError(f"unknown scenario {name_or_path!r} (known: {', '.join(builtin_names())}; "
                        "or give a path to a .toml file)")
