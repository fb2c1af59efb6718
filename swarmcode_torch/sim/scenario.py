"""Scenarios: the foraging worlds of the paper as data, loadable by name or from a TOML file.

What a scenario is (its dataclasses, its error, the bounds of its fields) is in
`scenario_types`, whether its packages can be placed in `placement`; both are importable from
here."""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

from .hardware import (
    MAX_NESTING,
    Catalog,
    CatalogError,
    catalog_from_dict,
    default_catalog,
    nesting_depth,
    parse_catalog,
)
from .placement import check_placement
from .reading import FileTooLargeError, NotRegularFileError, read_regular, tomllib
from .scenario_types import (
    EFFECTORS,
    FIELDS,
    MAX_ARENA,
    MAX_DESCRIPTION,
    MAX_EPISODE_TICKS,
    MAX_FILE_BYTES,
    MAX_GRIPS,
    MAX_NAME,
    MAX_NUMBER,
    MAX_PACKAGES,
    MAX_PATH,
    OBSTACLE_FIELDS,
    PACKAGE_CLEARANCE,
    PACKAGE_FIELDS,
    ROBOT_RADII,
    SCALAR_FIELDS,
    PackageClass,
    Scenario,
    ScenarioError,
)

__all__ = [
    "EFFECTORS",
    "FIELDS",
    "MAX_ARENA",
    "MAX_DESCRIPTION",
    "MAX_EPISODE_TICKS",
    "MAX_FILE_BYTES",
    "MAX_GRIPS",
    "MAX_NAME",
    "MAX_NUMBER",
    "MAX_PACKAGES",
    "MAX_PATH",
    "OBSTACLE_FIELDS",
    "PACKAGE_CLEARANCE",
    "PACKAGE_FIELDS",
    "ROBOT_RADII",
    "SCALAR_FIELDS",
    "PackageClass",
    "Scenario",
    "ScenarioError",
    "builtin_names",
    "check_placement",
    "decode_text",
    "load_scenario",
    "parse_scenario",
    "read_limited",
    "read_scenario",
    "scenario_from_dict",
]


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


def _scalars(d: dict) -> tuple[str, float, float, int, int, float]:
    """name, arena, base_radius, num_robots, episode_ticks, species_overhead, checked."""
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
    return name, arena, base_radius, num_robots, ticks, overhead


def _obstacles(d: dict) -> tuple[int, tuple[float, float]]:
    """The [obstacles] table: count and radius range, checked."""
    obs = d.get("obstacles", {})
    if not isinstance(obs, dict):
        raise ScenarioError("obstacles: expected a table")
    obs_count = _get(obs, "count", "obstacles.", int, default=0, required=False)
    if obs_count < 0:
        raise ScenarioError(f"obstacles.count: must be >= 0, got {obs_count}")
    obs_radius = _range(obs, "radius", "obstacles.", default=(0.5, 1.0))
    for k in obs:
        if k not in OBSTACLE_FIELDS:
            raise ScenarioError(f"obstacles.{k}: unknown field (known: count, radius)")
    return obs_count, obs_radius


def _package_class(i: int, p) -> PackageClass:
    """One [[packages]] table (the i-th), checked."""
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
        if k not in PACKAGE_FIELDS:
            raise ScenarioError(f"{w}{k}: unknown field")
    return PackageClass(kind, count, dist, mass, grips, band, dw, size)


def _package_classes(d: dict) -> tuple[PackageClass, ...]:
    """The [[packages]] tables, checked (at least one package in all, at most MAX_PACKAGES)."""
    pkgs = d.get("packages")
    if not isinstance(pkgs, list) or not pkgs:
        raise ScenarioError("packages: expected at least one [[packages]] table")
    classes = [_package_class(i, p) for i, p in enumerate(pkgs)]
    if sum(c.count for c in classes) < 1:
        raise ScenarioError("packages: the scenario places no package")
    if sum(c.count for c in classes) > MAX_PACKAGES:
        raise ScenarioError(
            f"packages: {sum(c.count for c in classes)} packages, more than "
            f"{MAX_PACKAGES} (each is placed one by one in every environment)"
        )
    return tuple(classes)


def _scenario_from_dict(
    d: dict, source: str, folder: Path | None = None, hardware: Catalog | None = None
) -> Scenario:
    if not isinstance(d, dict):
        raise ScenarioError(f"{source}: expected a table")
    known = set(FIELDS)
    for k in d:
        if k not in known:
            raise ScenarioError(f"{k}: unknown field (known: {', '.join(sorted(known))})")
    name, arena, base_radius, num_robots, ticks, overhead = _scalars(d)
    obs_count, obs_radius = _obstacles(d)
    classes = _package_classes(d)
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
        classes,
        hardware,
    )
    check_placement(scenario)
    return scenario


def builtin_names() -> list[str]:
    """Names of the built-in scenarios."""
    files = resources.files("swarmcode_torch").joinpath("scenarios").iterdir()
    return sorted(f.name[:-5] for f in files if f.name.endswith(".toml"))


def read_limited(path: Path, source: str, limit: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of a regular file, at most `limit` of them (ScenarioError naming `source` for
    one that cannot be read, is not a regular file or is larger: nothing past `limit` is
    read; `reading.read_regular`)."""
    try:
        return read_regular(path, limit)
    except NotRegularFileError:
        raise ScenarioError(f"{source}: not a regular file") from None
    except FileTooLargeError as e:
        if e.size is None:
            raise ScenarioError(
                f"{source}: more than the {limit} bytes a scenario or catalog file may have"
            ) from None
        raise ScenarioError(
            f"{source}: {e.size} bytes, more than the {limit} a scenario or catalog file may have"
        ) from None
    except OSError as e:
        raise ScenarioError(
            f"{source}: cannot be read ({e.strerror or type(e).__name__})"
        ) from None


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
    """A built-in scenario by name, or a scenario TOML file by path (`read_scenario`).

    Args:
        name_or_path: a name of `builtin_names()`, or the path of a scenario TOML file.
        hardware: a hardware catalog to use instead of the file's (its `hardware` file name is
            looked up beside it) or the built-in one.

    Returns:
        The `Scenario`.

    Raises:
        ScenarioError: (a ValueError) an unknown name or a file that is not a valid scenario.
    """
    return read_scenario(name_or_path, hardware)[0]
