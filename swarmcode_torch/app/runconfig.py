"""A run's config and scenario: config.toml written and read back (through the migrations),
the run's own scenario.toml and hardware.toml copies, and the checks a config passes before a
run starts (its settings, then the memory it needs)."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import tomli_w
import torch

from ..coevo.config import SettingError, SwarmCoDeConfig
from ..sim.hardware import (
    Catalog,
    CatalogError,
    catalog_toml_lines,
    default_catalog,
    default_catalog_bytes,
    parse_catalog,
)
from ..sim.scenario import EFFECTORS, Scenario, load_scenario, parse_scenario
from . import records
from .files import (
    CONFIG_FILE,
    HARDWARE_COPY,
    SCENARIO_COPY,
    RunError,
    atomic_write_bytes,
    check_nesting,
    read_file_bytes,
    read_text,
)
from .migrations import migrate_config, retired_value
from .settings import setting_message

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

#: The memory assumed when the machine's cannot be read.
FALLBACK_MEMORY = 64 * 2**30


# ------------------------------------------------------------------ config.toml
def config_table(cfg: SwarmCoDeConfig) -> dict[str, Any]:
    """The keys config.toml holds: every set key of `cfg`; TOML has no null, so a key unset where
    its default is set (quota_size_exponent) is "none", which reading a config turns back into
    None."""
    defaults = SwarmCoDeConfig().to_dict()
    return {
        k: (v if v is not None else "none")
        for k, v in cfg.to_dict().items()
        if v is not None or defaults.get(k) is not None
    }


def config_to_toml(
    cfg: SwarmCoDeConfig,
    software: dict | None = None,
    parent: dict | None = None,
    header: str | None = None,
) -> str:
    """config.toml: every set key of `cfg` (`config_table`), written by tomli-w; `software`
    (`records.software`), what wrote it, goes into a comment line (a config file holds settings
    only); `parent`, the run and generation a branched run started from, into a [parent]
    table (`read_parent`); `header`: the first comment line, if not a run's."""
    lines = [
        header
        or "# swarmcode-torch run configuration (re-run with: swarmcode-torch evolve --resume DIR)"
    ]
    if software:
        lines.append(
            "# written by " + ", ".join(f"{k} {v}" for k, v in software.items() if v is not None)
        )
    table: dict[str, Any] = config_table(cfg)
    if parent:
        table[PARENT_TABLE] = dict(parent)
    return "\n".join(lines) + "\n" + tomli_w.dumps(table)


#: The table of config.toml that names the run (and generation) a branched run started from.
PARENT_TABLE = "parent"


def write_config(run_dir: Path, cfg: SwarmCoDeConfig, parent: dict | None = None) -> None:
    """config.toml of `run_dir`, written atomically; `parent`: the [parent] table of a branched
    run (`config_to_toml`)."""
    atomic_write_bytes(
        Path(run_dir) / CONFIG_FILE,
        config_to_toml(cfg, records.software(cfg.device), parent).encode(),
    )


def config_from_dict(d: Any, source: str) -> SwarmCoDeConfig:
    """A validated config from a parsed table (config.toml, a checkpoint's "config") of any
    version; RunError naming `source` and the key for anything malformed or out of range."""
    problem = retired_value(d) if isinstance(d, dict) else None
    if problem:
        raise RunError(f"{source}: {problem}")
    try:
        cfg = SwarmCoDeConfig.from_dict(migrate_config(d))
        # a run made on a larger machine can still be inspected and replayed here; a resume
        # checks the memory it needs (`resume`)
        cfg.validate()
    except (TypeError, ValueError) as e:
        raise RunError(f"{source}: malformed config ({e})") from None
    return cfg


def _read_toml(path: Path) -> dict:
    """A TOML file of settings (config.toml, a --config file), read with tomllib (no code in it
    can run), without following a link and up to `MAX_TEXT_BYTES`; RunError naming the file."""
    text = read_text(path)
    check_nesting(text, str(path))
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise RunError(f"{path}: malformed config ({e})") from None
    except RecursionError:
        raise RunError(f"{path}: nested too deeply") from None


def _split_parent(d: dict, path: Path) -> tuple[dict, dict | None]:
    """(the settings of a config table, its [parent] table or None); RunError for a parent
    that is not a table."""
    if PARENT_TABLE not in d:
        return d, None
    d = dict(d)
    parent = d.pop(PARENT_TABLE)
    if not isinstance(parent, dict):
        raise RunError(
            f"{path}: [{PARENT_TABLE}] must be a table (run, generation), got {parent!r:.60}"
        )
    return d, parent


def read_config(run_dir: Path) -> SwarmCoDeConfig:
    """The config of a run directory, every value checked (`SwarmCoDeConfig.validate`); its
    [parent] table, if any, is not a setting (`read_parent`)."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise RunError(f"{run_dir} is not a run directory (no {CONFIG_FILE})")
    d, _ = _split_parent(_read_toml(path), path)
    missing = [k for k in CONFIG_REQUIRED if k not in d]
    if missing:
        # an empty or cut config would read as the defaults: another run than the one made
        raise RunError(
            f"{path}: {'empty' if not d else 'incomplete'} config (no "
            f"{', '.join(missing)}); restore it from the run's checkpoint or backup"
        )
    return config_from_dict(d, str(path))


def read_parent(run_dir: Path) -> dict | None:
    """The [parent] table of a run's config.toml ({"run": its directory, "generation": the
    generation it branched at, "checkpoint": the file it started from}), None for a run that
    was not branched from another (or has no readable config.toml)."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file() or path.is_symlink():
        return None
    try:
        return _split_parent(_read_toml(path), path)[1]
    except RunError:
        return None


def read_config_file(path: Path, base: SwarmCoDeConfig | None = None) -> SwarmCoDeConfig:
    """The config of a settings file (`read_config_file_keys`)."""
    return read_config_file_keys(path, base)[0]


def read_config_file_keys(
    path: Path, base: SwarmCoDeConfig | None = None
) -> tuple[SwarmCoDeConfig, frozenset[str]]:
    """(the config, the keys the file sets) of a settings file in config.toml's format
    (`evolve --config FILE`; a run's own config.toml will do: its [parent] table is ignored): its keys over `base` (default: the
    preset the file names, else the default preset), not yet checked (`check_start` does).
    RunError, one line, naming the file and the key for an unknown key or a malformed value."""
    from ..coevo.config import PRESETS, preset_config

    path = Path(path)
    if path.is_symlink():
        raise RunError(f"{path} is a symbolic link; give the config file itself")
    if not path.is_file():
        raise RunError(f"{path} is not a file (no such config file)")
    d, _ = _split_parent(_read_toml(path), path)
    known = set(SwarmCoDeConfig().to_dict())
    for k, v in d.items():
        if k not in known:
            raise RunError(
                f"{path}: unknown key {k!r} (a config file holds the keys of a run's {CONFIG_FILE})"
            )
        if isinstance(v, (dict, list)):
            raise RunError(f"{path}: {k}: expected a single value, got {v!r:.60}")
    d = {k: (None if v == "none" else v) for k, v in d.items()}
    if base is None:
        preset = d.get("preset")
        base = preset_config(preset) if preset in PRESETS else SwarmCoDeConfig()
    try:
        return SwarmCoDeConfig.from_dict({**base.to_dict(), **d}), frozenset(d)
    except (TypeError, ValueError) as e:
        raise RunError(f"{path}: malformed config ({e})") from None


#: Keys every config.toml a run has written holds (each version wrote them all).
CONFIG_REQUIRED = ("scenario", "generations", "population", "seed")


# ------------------------------------------------------------------ a Scenario object as TOML
def scenario_to_toml(s: Scenario) -> str:
    """A scenario TOML file (written by tomli-w) that loads back (`load_scenario`) as a scenario
    equal to `s`."""
    names = {v: k for k, v in EFFECTORS.items()}
    packages = []
    for p in s.packages:
        grips = (
            {"effector": names[p.grips[0]]}
            if p.kind == "individual"
            else {"grips": [names[g] for g in p.grips]}
        )
        packages.append(
            {
                "kind": p.kind,
                **grips,
                "count": int(p.count),
                "distance": [float(x) for x in p.distance],
                "mass": [float(x) for x in p.mass],
                "radius_band": [float(x) for x in p.radius_band],
                "size": float(p.size),
                "distance_weighting": bool(p.distance_weighting),
            }
        )
    table: dict[str, Any] = {
        "name": s.name,
        "description": s.description,
        "arena": float(s.arena),
        "base_radius": float(s.base_radius),
        "num_robots": int(s.num_robots),
        "episode_ticks": int(s.episode_ticks),
        "species_overhead": float(s.species_overhead),
        "obstacles": {
            "count": int(s.obstacle_count),
            "radius": [float(x) for x in s.obstacle_radius],
        },
        "packages": packages,
    }
    text = tomli_w.dumps(table)
    if s.hardware != default_catalog():  # its own catalog, inline
        text += "\n".join(catalog_toml_lines(s.hardware, prefix="hardware.")) + "\n"
    return text


def scenario_data(s: Scenario) -> bytes:
    """The TOML of a Scenario object, checked to load back as the same scenario (parsing it
    validates it: ScenarioError names the field)."""
    from ..sim.scenario import PackageClass

    if not isinstance(s, Scenario):
        raise TypeError(f"scenario must be a name, a path or a Scenario, got {type(s).__name__}")
    packages = s.packages if isinstance(s.packages, (list, tuple)) else None
    if packages is None or not all(isinstance(p, PackageClass) for p in packages):
        bad = (
            type(s.packages).__name__
            if packages is None
            else next(type(p).__name__ for p in packages if not isinstance(p, PackageClass))
        )
        raise TypeError(
            f"scenario {str(s.name)[:60]!r}: packages must be PackageClass objects, got {bad} "
            "(or load the scenario from a TOML file: load_scenario)"
        )
    data = scenario_to_toml(s).encode("utf-8")
    if parse_scenario(data, f"scenario {s.name!r}") != s:
        raise ValueError(f"scenario {s.name!r} does not survive a round trip through TOML")
    return data


# ------------------------------------------------------------------ a run's own scenario
def hardware_bytes(hardware: Catalog | None = None) -> bytes:
    """What a run keeps as its hardware.toml: the installed catalog file as read
    (swarmcode_torch/data/hardware.toml) when the run uses it, else the run's scenario's own
    catalog written out as TOML (it parses back to the same catalog)."""
    if hardware is None or hardware == default_catalog():
        return default_catalog_bytes()
    head = [
        "# The hardware catalog of this run's scenario (its `hardware` key), as the run read it.",
        "# Tiers are listed 1, 2, 3. Units and the meaning of each field: data/hardware.toml.",
    ]
    return ("\n".join(head + catalog_toml_lines(hardware)) + "\n").encode("utf-8")


def write_run_files(
    run_dir: Path, cfg: SwarmCoDeConfig, scenario_data: bytes, hardware: Catalog | None = None
) -> None:
    """config.toml, and the copies that make a new run self-contained: scenario.toml (the bytes
    its scenario was read from) and hardware.toml (the catalog its robots are built from,
    `hardware_bytes`)."""
    run_dir = Path(run_dir)
    write_config(run_dir, cfg)
    atomic_write_bytes(run_dir / SCENARIO_COPY, scenario_data)
    atomic_write_bytes(run_dir / HARDWARE_COPY, hardware_bytes(hardware))


def run_scenario_source(run_dir: Path, cfg: SwarmCoDeConfig) -> str:
    """Where the scenario of a run is read from: its scenario.toml copy (an absolute path, so
    any working directory will do), or, in a run directory made before runs kept one, the
    config's scenario."""
    copy = Path(run_dir) / SCENARIO_COPY
    return str(copy.absolute()) if copy.is_file() or copy.is_symlink() else cfg.scenario


def run_catalog(run_dir: Path) -> Catalog | None:
    """The hardware catalog a run ran with: its hardware.toml copy (RunError when that cannot be
    read or is not a valid catalog), or None for a run made before runs kept one (it used the
    installed catalog)."""
    copy = Path(run_dir) / HARDWARE_COPY
    if not copy.is_file() and not copy.is_symlink():
        return None
    try:
        data = read_file_bytes(copy)
    except OSError as e:
        raise RunError(f"{copy}: cannot be read ({e.strerror or type(e).__name__})") from None
    try:
        return parse_catalog(data, str(copy))
    except CatalogError as e:
        raise RunError(str(e)) from None


def run_scenario(run_dir: Path, cfg: SwarmCoDeConfig) -> Scenario:
    """The scenario a run ran on (see `run_scenario_source`), its robots built from the run's
    own hardware.toml (`run_catalog`): whatever has become of the installed catalog or of the
    file the scenario named, a resumed or replayed run computes with the catalog it started
    with."""
    copy = Path(run_dir) / SCENARIO_COPY
    catalog = run_catalog(run_dir)
    if not copy.is_file() and not copy.is_symlink():
        return load_scenario(cfg.scenario, catalog)  # a run made before runs kept copies
    try:
        data = read_file_bytes(copy)  # never through a link
    except OSError as e:
        raise RunError(f"{copy} cannot be read ({e.strerror or type(e).__name__})") from None
    return parse_scenario(data, str(copy.absolute()), copy.parent, catalog)


def config_differences(
    a: SwarmCoDeConfig,
    b: SwarmCoDeConfig,
    scenario: Scenario | None = None,
    ignore: Iterable[str] = ("generations", "device"),
) -> list[str]:
    """The config keys in which `a` and `b` differ (except `ignore`); an unset swarm_size or
    ticks counts as the scenario's (what a run pins when it starts)."""
    da, db = a.to_dict(), b.to_dict()
    if scenario is not None:
        for d in (da, db):
            if d["swarm_size"] is None:
                d["swarm_size"] = scenario.num_robots
            if d["ticks"] is None:
                d["ticks"] = scenario.episode_ticks
    ignore = set(ignore)
    return sorted(k for k in da if k not in ignore and da[k] != db[k])


# ------------------------------------------------------------------ memory
def memory_limit(device: str = "auto") -> tuple[int, str]:
    """(bytes, what) of the memory a run's evaluation batch lives in: the total memory of the
    CUDA device it would run on, or this machine's physical memory; FALLBACK_MEMORY (64 GiB)
    when neither can be read."""
    try:
        if device != "cpu" and torch.cuda.is_available():
            idx = torch.device("cuda" if device == "auto" else device).index or 0
            if idx < torch.cuda.device_count():
                return torch.cuda.get_device_properties(idx).total_memory, f"cuda:{idx} memory"
        if device == "cpu" or not device.startswith("cuda"):
            n = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
            if n > 0:
                return n, "memory"
    except (ValueError, OSError, RuntimeError, AttributeError):
        pass
    return FALLBACK_MEMORY, "assumed memory (64 GiB)"


def estimate_bytes(cfg: SwarmCoDeConfig, scenario: Scenario | None = None) -> int:
    """A rough estimate of the memory one generation needs (a lower bound of the peak, close to
    the measured peak of a swarm1000 generation), in bytes:

    - the evaluation batch: E = 2 x population x trials environments (or the `reeval_trials` of
      the best team's re-evaluation, where they are more) of N robots (the swarm
      size; the scenario's robots; 1 when unknown), 16 x (16 + C + min(N, 500)) bytes a robot
      (state and constants, distances to the C grip points of the packages, contact pairs);
    - the layouts: population x trials environments of 32 candidate positions for each of the
      K packages (checked against the O obstacles) and each obstacle: 4 x 32 x (K (O + 4) + 2 O);
    - the start slots: 3 x 8 x N^2 bytes (pairwise distances of the N robots' slots);
    - the programs: population x (4 x 11,664 lookup-table entries + 16 x bt_length + tag_length).
    """
    from ..sim.bt import NUM_COMBOS

    P, T = cfg.population, cfg.trials
    if scenario is not None:
        N = cfg.swarm_size or scenario.num_robots
        C = sum(c.count * len(c.grips) for c in scenario.packages)
        K, O = scenario.num_packages, scenario.obstacle_count
    else:
        N, C, K, O = cfg.swarm_size or 1, 1, 1, 0
    envs = max(2 * P * T, cfg.reeval_trials)
    batch = envs * N * 16 * (16 + C + min(N, 500))
    layouts = P * T * 4 * 32 * (K * (O + 4) + 2 * O)
    # the start slots: pairwise distances of the scenario's robots, three [N, N] float64
    # tensors at once (layout.spawn_slots: cdist, eye, their sum)
    M = max(N, scenario.num_robots if scenario is not None else 1)
    layouts += 3 * 8 * M * M
    programs = P * (4 * NUM_COMBOS + 16 * cfg.bt_length + cfg.tag_length)
    return batch + layouts + programs


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"):
        if n < 1024 or unit == "EiB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.3g} EiB"  # pragma: no cover


def check_memory(
    cfg: SwarmCoDeConfig,
    scenario: Scenario | None = None,
    option_names: dict[str, str] | None = None,
) -> None:
    """ValueError, before anything is allocated, when `estimate_bytes` exceeds `memory_limit`:
    the message gives the estimate and the settings that size it, by their config keys
    (`population`, as the API takes them) or as `option_names` spells them (--population)."""
    need = estimate_bytes(cfg, scenario)
    limit, what = memory_limit(cfg.device if isinstance(cfg.device, str) else "auto")
    if need <= limit:
        return
    names = {
        "population": "population",
        "trials": "trials",
        "swarm_size": "swarm_size",
        **(option_names or {}),
    }
    N = cfg.swarm_size or (scenario.num_robots if scenario is not None else 1)
    robots = (
        f"{N} robots"
        if cfg.swarm_size or scenario is None
        else f"{N} robots (num_robots of scenario {cfg.scenario})"
    )
    raise ValueError(
        f"this run would need about {_size(need)} of memory, more than the {_size(limit)} of "
        f"{what}: {2 * cfg.population * cfg.trials} environments of {robots} a generation "
        f"(2 x population x trials) and the programs of {cfg.population} individuals of "
        f"bt_length {cfg.bt_length}; use a smaller {names['population']}, {names['trials']} or "
        f"{names['swarm_size']}"
    )


def check_config(
    cfg: SwarmCoDeConfig,
    scenario: Scenario | None = None,
    option_names: dict[str, str] | None = None,
) -> None:
    """Everything a run's config must pass before anything is made: its settings' types and
    ranges, then the memory its sizes need (so that sizes far too large are told what they
    would need), then the upper bounds that memory does not bound. ValueError, one line, that
    names a setting by its key or as `option_names` spells it (`settings.setting_message`)."""
    try:
        cfg.validate(bounds=False)
        check_memory(cfg, scenario, option_names)
        cfg.check_bounds()
    except SettingError as e:
        raise ValueError(setting_message(e, option_names)) from None
