"""Scenarios: the foraging worlds of the paper as data, loadable by name or from a TOML file."""

from __future__ import annotations

import math
import os
import stat
import sys
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from .hardware import (
    MAX_NESTING,
    R_MAX,
    R_MIN,
    Catalog,
    CatalogError,
    catalog_from_dict,
    default_catalog,
    nesting_depth,
    parse_catalog,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

EFFECTORS = {"suction": 0, "pincher": 1}
MAX_GRIPS = 3
#: Robot radii the hardware genes can take.
ROBOT_RADII = (R_MIN, R_MAX)
#: Upper bounds of a scenario's sizes: beyond them a world is certainly not what was meant.
MAX_ARENA = 10_000.0  # m
MAX_EPISODE_TICKS = 1_000_000
MAX_NUMBER = 1e15  # any number of a scenario: float32 holds it with room to spare
#: The most bytes read from a scenario file or the hardware catalog file it names.
MAX_FILE_BYTES = 16 * 2**20
#: The longest scenario name, description and --scenario name or path (characters).
MAX_NAME = 200
MAX_DESCRIPTION = 10_000
MAX_PATH = 4096
#: The most packages a scenario places (each environment places and senses every one).
MAX_PACKAGES = 10_000
#: Room kept free around a package for a robot at each grip (layout.make_layouts: size + 0.6).
PACKAGE_CLEARANCE = 0.6
#: The scalar fields of a scenario file, in the order a written one gives them (the tables
#: `obstacles`, `packages` and `hardware` follow).
SCALAR_FIELDS = (
    "name",
    "description",
    "arena",
    "base_radius",
    "num_robots",
    "episode_ticks",
    "species_overhead",
)


class ScenarioError(ValueError):
    """A scenario that cannot be loaded; the message names the bad field."""


@dataclass(frozen=True)
class PackageClass:
    """A group of packages that share a spec; `count` of them are placed in every environment."""

    kind: str  # "individual" or "collab"
    count: int
    distance: tuple[float, float]  # from the base centre (m)
    mass: tuple[float, float]  # kg; heavier near the base when distance_weighting
    grips: tuple[int, ...]  # effector of each grip point (one for an individual package)
    radius_band: tuple[float, float] = (0.0, 10.0)  # robot radii that can lift it (m)
    distance_weighting: bool = False
    size: float = 0.2  # package radius (m); grip points lie just outside it

    @property
    def label(self) -> str:
        """e.g. 'pincher 16-24 kg, r 0.32-0.5 m' or 'collab suction+pincher 30-40 kg'."""
        names = {v: k for k, v in EFFECTORS.items()}
        eff = "+".join(names[e] for e in self.grips)
        collab = "collab " if self.kind == "collab" else ""
        text = f"{collab}{eff} {self.mass[0]:g}-{self.mass[1]:g} kg"
        if self.radius_band != (0.0, 10.0):
            text += f", r {self.radius_band[0]:g}-{self.radius_band[1]:g} m"
        return text


@dataclass(frozen=True)
class Scenario:
    """A foraging world: arena, base, obstacles, packages and swarm size."""

    name: str
    description: str
    arena: float  # side of the square arena (m); the base is at its centre
    base_radius: float
    num_robots: int
    episode_ticks: int
    species_overhead: float  # $ fabrication overhead per distinct species in a team
    obstacle_count: int
    obstacle_radius: tuple[float, float]
    packages: tuple[PackageClass, ...]
    #: the hardware catalog its robots are built from: the scenario's own (its `hardware` key)
    #: or the built-in one (data/hardware.toml)
    hardware: Catalog = field(default_factory=default_catalog)

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
    if kind is int and abs(v) > MAX_NUMBER:
        text = str(v) if len(str(v)) <= 30 else f"{str(v)[:12]}... ({len(str(v))} digits)"
        raise ScenarioError(
            f"{where}{key}: expected an integer of at most {MAX_NUMBER:g}, got {text}"
        )
    if kind is float and not (math.isfinite(v) and abs(v) <= MAX_NUMBER):
        raise ScenarioError(
            f"{where}{key}: expected a finite number (at most {MAX_NUMBER:g} in size), got {v!r}"
        )
    return v


def _range(d: dict, key: str, where: str, default=None, lo: float = 0.0) -> tuple[float, float]:
    v = d.get(key, default)
    if v is None:
        raise ScenarioError(f"{where}{key}: missing")
    if (
        not isinstance(v, (list, tuple))
        or len(v) != 2
        or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
    ):
        raise ScenarioError(f"{where}{key}: expected [low, high], got {v!r}")
    a, b = float(v[0]), float(v[1])
    if not all(math.isfinite(x) and abs(x) <= MAX_NUMBER for x in (a, b)):
        raise ScenarioError(
            f"{where}{key}: expected finite numbers [low, high] (at most "
            f"{MAX_NUMBER:g} in size), got {v!r}"
        )
    if a < lo or b < a:
        raise ScenarioError(f"{where}{key}: expected {lo} <= low <= high, got {v!r}")
    return a, b


def _effector(name, where: str) -> int:
    if name not in EFFECTORS:
        raise ScenarioError(f"{where}: unknown effector {name!r} (known: suction, pincher)")
    return EFFECTORS[name]


def scenario_from_dict(
    d: dict, source: str = "scenario", folder: Path | None = None, hardware: Catalog | None = None
) -> Scenario:
    """Build and validate a :class:`Scenario` from a parsed TOML table: every field's type and
    range (finite numbers only), and whether its packages can be placed (`check_placement`).
    ScenarioError names the source and the field. `folder`: where a `hardware` file name is
    looked up (the scenario file's folder); `hardware`: a catalog to use instead of the one the
    scenario names (a run directory's own copy)."""
    try:
        return _scenario_from_dict(d, source, folder, hardware)
    except ScenarioError as e:
        raise ScenarioError(f"{source}: {e}") from None


def _hardware(v, folder: Path | None) -> Catalog:
    """The catalog a scenario's `hardware` key names: a TOML file (a path relative to the
    scenario file's folder) or an inline table with the sections of data/hardware.toml (the
    caller has checked that it is one of the two)."""
    if isinstance(v, str):
        if folder is None:
            raise ScenarioError(
                f"hardware: {v!r} is a file name, but this scenario has no "
                "folder to find it in (give the catalog inline as a table)"
            )
        if len(v) > MAX_PATH or "\0" in v:
            raise ScenarioError(f"hardware: not a file name ({len(v)} characters)")
        path = folder / v
        # the catalog lies beside the scenario (README): a path that leads out of its folder
        # (an absolute path, '..', a link) is refused before anything is read
        try:
            real, home = path.resolve(), folder.resolve()
        except (OSError, RuntimeError) as e:
            raise ScenarioError(
                f"hardware: {v!r:.100} cannot be resolved "
                f"({getattr(e, 'strerror', None) or type(e).__name__})"
            ) from None
        if not real.is_relative_to(home):
            raise ScenarioError(
                f"hardware: {v!r:.100} is outside the scenario's folder {home}; "
                "the catalog file must lie in that folder"
            )
        if not real.is_file():
            raise ScenarioError(f"hardware: catalog file not found: {path}")
        data = read_limited(real, f"hardware: {path}")
        try:
            return parse_catalog(data, f"hardware ({path})")
        except CatalogError as e:
            raise ScenarioError(str(e)) from None
    try:
        return catalog_from_dict(v, "hardware")
    except CatalogError as e:
        raise ScenarioError(str(e)) from None


def _scenario_from_dict(
    d: dict, source: str, folder: Path | None = None, hardware: Catalog | None = None
) -> Scenario:
    if not isinstance(d, dict):
        raise ScenarioError(f"{source}: expected a table")
    known = {*SCALAR_FIELDS, "obstacles", "packages", "hardware"}
    for k in d:
        if k not in known:
            raise ScenarioError(f"{k}: unknown field (known: {', '.join(sorted(known))})")
    name = _get(d, "name", "", str)
    if not name.strip() or len(name) > MAX_NAME or not name.isprintable():
        raise ScenarioError(
            f"name: expected 1 to {MAX_NAME} printable characters, got "
            f"{len(name)} characters {name[:40]!r}"
        )
    arena = _get(d, "arena", "", float)
    base_radius = _get(d, "base_radius", "", float)
    num_robots = _get(d, "num_robots", "", int)
    ticks = _get(d, "episode_ticks", "", int)
    overhead = _get(d, "species_overhead", "", float, default=0.0, required=False)
    if not 0 < arena <= MAX_ARENA:
        raise ScenarioError(f"arena: must be in (0, {MAX_ARENA:g}] m, got {arena}")
    if not 0 < base_radius < arena / 2:
        raise ScenarioError(f"base_radius: must be in (0, arena/2), got {base_radius}")
    if num_robots < 1:
        raise ScenarioError(f"num_robots: must be >= 1, got {num_robots}")
    if not 1 <= ticks <= MAX_EPISODE_TICKS:
        raise ScenarioError(f"episode_ticks: must be in [1, {MAX_EPISODE_TICKS}], got {ticks}")
    if overhead < 0:
        raise ScenarioError(f"species_overhead: must be >= 0, got {overhead}")

    obs = d.get("obstacles", {})
    if not isinstance(obs, dict):
        raise ScenarioError("obstacles: expected a table")
    obs_count = _get(obs, "count", "obstacles.", int, default=0, required=False)
    if obs_count < 0:
        raise ScenarioError(f"obstacles.count: must be >= 0, got {obs_count}")
    obs_radius = _range(obs, "radius", "obstacles.", default=(0.5, 1.0))
    for k in obs:
        if k not in {"count", "radius"}:
            raise ScenarioError(f"obstacles.{k}: unknown field (known: count, radius)")

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
        mass = _range(p, "mass", w)
        grips: tuple[int, ...]
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
            if k not in {
                "kind",
                "count",
                "distance",
                "mass",
                "effector",
                "grips",
                "radius_band",
                "size",
                "distance_weighting",
            }:
                raise ScenarioError(f"{w}{k}: unknown field")
        classes.append(PackageClass(kind, count, dist, mass, grips, band, dw, size))
    if sum(c.count for c in classes) < 1:
        raise ScenarioError("packages: the scenario places no package")
    if sum(c.count for c in classes) > MAX_PACKAGES:
        raise ScenarioError(
            f"packages: {sum(c.count for c in classes)} packages, more than "
            f"{MAX_PACKAGES} (each is placed one by one in every environment)"
        )
    description = d.get("description", "")
    if not isinstance(description, str):
        raise ScenarioError(f"description: expected str, got {description!r:.60}")
    if len(description) > MAX_DESCRIPTION:
        raise ScenarioError(
            f"description: {len(description)} characters, at most {MAX_DESCRIPTION}"
        )
    named = d.get("hardware")
    if named is not None and not (isinstance(named, dict) or isinstance(named, str) and named):
        raise ScenarioError(f"hardware: expected a file name or a table, got {named!r}")
    if hardware is None:  # else the given catalog stands in for the one the key names
        hardware = default_catalog() if named is None else _hardware(named, folder)
    scenario = Scenario(
        name,
        description,
        arena,
        base_radius,
        num_robots,
        ticks,
        overhead,
        obs_count,
        obs_radius,
        tuple(classes),
        hardware,
    )
    check_placement(scenario)
    return scenario


def check_placement(s: Scenario) -> None:
    """ScenarioError unless the packages and obstacles of `s` can be placed the way
    `layout.make_layouts` places them. These are necessary conditions, kept simple:

    - every obstacle fits in the arena (2 x radius < arena), and the obstacles cover at most
      half of it (count x pi x low radius^2);
    - a package's grip band meets the robot radii [0.15, 0.5] m;
    - its distance range starts outside the base (low >= base_radius + size), its nearest
      distance is inside the arena in every direction (low <= arena/2 - clearance) and its
      farthest at most reaches the corners (high <= (arena/2 - clearance) x sqrt 2), where the
      clearance is size + 0.6 m (the room a robot needs at each grip);
    - its packages, as discs of radius clearance, fit in the ring their distances allow, and all
      packages and obstacles together fit in the arena outside the base.
    """
    W, base = s.arena, s.base_radius
    lo_r, hi_r = s.obstacle_radius
    if s.obstacle_count:
        if 2 * hi_r >= W:
            raise ScenarioError(
                f"obstacles.radius: an obstacle of radius {hi_r:g} m does not fit "
                f"in a {W:g} m arena"
            )
        if s.obstacle_count * math.pi * lo_r**2 > W * W / 2:
            raise ScenarioError(
                f"obstacles: {s.obstacle_count} obstacles of radius >= {lo_r:g} m "
                f"cover more than half of the {W:g} m arena; packages could not "
                "be placed clear of them"
            )
    used = s.obstacle_count * math.pi * lo_r**2
    for i, c in enumerate(s.packages):
        w = f"packages[{i}]."
        band_lo, band_hi = c.radius_band
        if band_hi < ROBOT_RADII[0] or band_lo > ROBOT_RADII[1]:
            raise ScenarioError(
                f"{w}radius_band: [{band_lo:g}, {band_hi:g}] m holds no robot "
                f"radius (robots are {ROBOT_RADII[0]:g}-{ROBOT_RADII[1]:g} m)"
            )
        clear = c.size + PACKAGE_CLEARANCE
        d_lo, d_hi = c.distance
        if d_lo < base + c.size:
            raise ScenarioError(
                f"{w}distance: packages at {d_lo:g} m lie inside the base "
                f"(base_radius {base:g} m + size {c.size:g} m)"
            )
        if d_lo > W / 2 - clear:
            raise ScenarioError(
                f"{w}distance: {d_lo:g} m from the base centre lies outside the "
                f"arena in most directions (at most {W / 2 - clear:g} m: arena/2 "
                f"- size - {PACKAGE_CLEARANCE:g})"
            )
        if d_hi > (W / 2 - clear) * math.sqrt(2):
            raise ScenarioError(
                f"{w}distance: {d_hi:g} m lies outside the arena (at most "
                f"{(W / 2 - clear) * math.sqrt(2):.3g} m)"
            )
        need = c.count * math.pi * clear**2
        ring = min(math.pi * ((d_hi + clear) ** 2 - max(d_lo - clear, 0.0) ** 2), W * W)
        if need > ring:
            raise ScenarioError(
                f"{w}count: {c.count} packages of size {c.size:g} m do not fit "
                f"at {d_lo:g}-{d_hi:g} m from the base (they need {need:.4g} m2, "
                f"the ring holds {ring:.4g} m2)"
            )
        used += need
    if used > W * W - math.pi * base**2:
        raise ScenarioError(
            f"packages: the packages and obstacles need {used:.4g} m2, more than "
            f"the {W * W - math.pi * base**2:.4g} m2 of the arena outside the "
            "base"
        )


def builtin_names() -> list[str]:
    """Names of the built-in scenarios."""
    files = resources.files("swarmcode_torch").joinpath("scenarios").iterdir()
    return sorted(f.name[:-5] for f in files if f.name.endswith(".toml"))


def read_limited(path: Path, source: str, limit: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of a regular file, at most `limit` of them (ScenarioError naming `source` for
    one that cannot be read, is not a regular file or is larger: nothing past `limit` is
    read)."""
    try:
        with os.fdopen(os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0)), "rb") as f:
            st = os.fstat(f.fileno())
            if not stat.S_ISREG(st.st_mode):
                raise ScenarioError(f"{source}: not a regular file")
            if st.st_size > limit:
                raise ScenarioError(
                    f"{source}: {st.st_size} bytes, more than the {limit} a "
                    "scenario or catalog file may have"
                )
            data = f.read(limit + 1)
    except OSError as e:
        raise ScenarioError(
            f"{source}: cannot be read ({e.strerror or type(e).__name__})"
        ) from None
    if len(data) > limit:
        raise ScenarioError(
            f"{source}: more than the {limit} bytes a scenario or catalog file may have"
        )
    return data


def decode_text(data: bytes, source: str) -> str:
    """UTF-8 text (a leading byte-order mark is dropped); ScenarioError naming `source` for bytes
    that are not UTF-8."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise ScenarioError(
            f"{source}: not UTF-8 text (byte 0x{data[e.start]:02x} at offset {e.start})"
        ) from None


def parse_scenario(
    data: bytes, source: str, folder: Path | None = None, hardware: Catalog | None = None
) -> Scenario:
    """A scenario from the bytes of its TOML file (`folder`, `hardware`: `scenario_from_dict`)."""
    if len(data) > MAX_FILE_BYTES:
        raise ScenarioError(
            f"{source}: {len(data)} bytes, more than a scenario file may have ({MAX_FILE_BYTES})"
        )
    text = decode_text(data, source)
    depth = nesting_depth(text)
    if depth > MAX_NESTING:
        raise ScenarioError(f"{source}: nested {depth} levels deep (at most {MAX_NESTING})")
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{source}: not valid TOML ({e})") from None
    except RecursionError:
        raise ScenarioError(f"{source}: nested too deeply") from None
    return scenario_from_dict(d, source, folder, hardware)


def read_scenario(name_or_path: str, hardware: Catalog | None = None) -> tuple[Scenario, bytes]:
    """A built-in scenario by name, or a scenario TOML file by path, and the bytes it was read
    from (a run keeps them as its scenario.toml). A file's `hardware` file name is looked up
    beside it; `hardware`: a catalog to use instead (`scenario_from_dict`)."""
    if not isinstance(name_or_path, str) or not name_or_path:
        raise ScenarioError(f"scenario: expected a name or a path, got {name_or_path!r:.60}")
    if len(name_or_path) > MAX_PATH or "\0" in name_or_path:
        raise ScenarioError(
            f"scenario: a name or path of {len(name_or_path)} characters "
            f"{name_or_path[:40]!r}... (at most {MAX_PATH}, no NUL)"
        )
    if name_or_path in builtin_names():
        data = (
            resources.files("swarmcode_torch")
            .joinpath(f"scenarios/{name_or_path}.toml")
            .read_bytes()
        )
        return parse_scenario(data, name_or_path, None, hardware), data
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise ScenarioError(f"scenario file not found: {path}")
        data = read_limited(path, str(path))
        return parse_scenario(data, str(path), path.parent, hardware), data
    raise ScenarioError(
        f"unknown scenario {name_or_path!r} (known: {', '.join(builtin_names())}; "
        "or give a path to a .toml file)"
    )


def load_scenario(name_or_path: str, hardware: Catalog | None = None) -> Scenario:
    """A built-in scenario by name, or a scenario TOML file by path (`read_scenario`)."""
    return read_scenario(name_or_path, hardware)[0]
