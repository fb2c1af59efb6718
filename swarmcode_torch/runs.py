"""Run directories: config.toml, atomic checkpoints, and the generation loop with reporters."""

from __future__ import annotations

import io
import json
import math
import os
import pickle
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Protocol

import torch

from .evolve import Evolution, EvolveConfig

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

CONFIG_FILE = "config.toml"
CHECKPOINT_FILE = "checkpoint.pt"
SUMMARY_FILE = "summary.json"
TEAMS_FILE = "teams.jsonl"


class RunError(ValueError):
    """A run directory, config or checkpoint that cannot be used (one-line message)."""


class Reporter(Protocol):
    def on_start(self, ev: Evolution) -> None: ...
    def on_generation(self, ev: Evolution, metrics: dict) -> None: ...
    def on_end(self, ev: Evolution) -> None: ...


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write a file so that readers see the old or the new content, never a partial one."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


# ------------------------------------------------------------------ config.toml
def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    return json.dumps(str(v))


def config_to_toml(cfg: EvolveConfig) -> str:
    lines = ["# swarmcode-torch run configuration (re-run with: swarmcode-torch evolve --resume DIR)"]
    for k, v in cfg.to_dict().items():
        if v is not None:
            lines.append(f"{k} = {_toml_value(v)}")
    return "\n".join(lines) + "\n"


def write_config(run_dir: Path, cfg: EvolveConfig) -> None:
    atomic_write_bytes(Path(run_dir) / CONFIG_FILE, config_to_toml(cfg).encode())


def read_config(run_dir: Path) -> EvolveConfig:
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise RunError(f"{run_dir} is not a run directory (no {CONFIG_FILE})")
    try:
        return EvolveConfig.from_dict(tomllib.loads(path.read_text()))
    except (tomllib.TOMLDecodeError, TypeError, ValueError) as e:
        raise RunError(f"{path}: malformed config ({e})") from None


# ------------------------------------------------------------------ checkpoints
def save_checkpoint(run_dir: Path, ev: Evolution) -> Path:
    buf = io.BytesIO()
    torch.save(ev.state_dict(), buf)
    path = Path(run_dir) / CHECKPOINT_FILE
    atomic_write_bytes(path, buf.getvalue())
    return path


#: What a checkpoint may hold at the top level, and the type of each entry.
_CHECKPOINT_KEYS = {"version": int, "config": dict, "generation": int, "genome": dict,
                    "species_hint": torch.Tensor, "proto": (dict, type(None)),
                    "proto_ids": torch.Tensor, "next_species_id": int, "fitness": torch.Tensor,
                    "has_fitness": torch.Tensor, "rng_state": torch.Tensor,
                    "best": (dict, type(None)), "history": list}


def read_checkpoint(path: Path) -> dict:
    """The contents of a checkpoint file, unpickled with `torch.load(weights_only=True)`: only
    tensors, plain containers, numbers and strings are rebuilt, so no code in the file can run.
    RunError for a file that would call anything on loading, a damaged file, or one that is not a
    swarmcode-torch checkpoint."""
    path = Path(path)
    try:
        d = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        if "weights only load failed" in str(e).lower() or "unsupported global" in str(e).lower():
            raise RunError(f"{path} was refused: loading it would run code (only tensors, "
                           "numbers, strings and plain containers are allowed)") from None
        raise RunError(f"{path} is corrupt or not a checkpoint (UnpicklingError)") from None
    except OSError as e:
        raise RunError(f"{path} cannot be read ({e.strerror or type(e).__name__})") from None
    except Exception as e:  # noqa: BLE001 - any other failure means a damaged file
        raise RunError(f"{path} is corrupt or not a checkpoint ({type(e).__name__})") from None
    if not isinstance(d, dict) or "version" not in d:
        raise RunError(f"{path} is not a swarmcode-torch checkpoint")
    for key, kind in _CHECKPOINT_KEYS.items():
        if key not in d:
            raise RunError(f"{path} is not a complete checkpoint (no {key!r})")
        if not isinstance(d[key], kind) or isinstance(d[key], bool) and kind is int:
            raise RunError(f"{path} is damaged: {key!r} has the wrong type "
                           f"({type(d[key]).__name__})")
    return d


def load_checkpoint(run_dir: Path) -> dict:
    """The checkpoint of a run directory (see `read_checkpoint`)."""
    path = Path(run_dir) / CHECKPOINT_FILE
    if not path.is_file():
        raise RunError(f"{run_dir} has no {CHECKPOINT_FILE} to resume from")
    return read_checkpoint(path)


def resume(run_dir: Path, generations: int | None = None, device: str | None = None) -> Evolution:
    """The run in `run_dir`, continued from its checkpoint with its saved config."""
    cfg = read_config(run_dir)
    if generations is not None:
        cfg.generations = generations
    if device is not None:
        cfg.device = device
    d = load_checkpoint(run_dir)
    try:
        return Evolution.from_checkpoint(d, cfg)
    except (KeyError, TypeError, RuntimeError) as e:
        raise RunError(f"checkpoint in {run_dir} is incompatible ({type(e).__name__}: {e})") from None


def new_run_dir(logdir: Path, cfg: EvolveConfig) -> Path:
    name = Path(cfg.scenario).stem
    stamp = time.strftime("%Y%m%d-%H%M%S")
    d = Path(logdir) / f"{name}__{cfg.seed}__{stamp}"
    i = 1
    while d.exists():
        d = Path(logdir) / f"{name}__{cfg.seed}__{stamp}-{i}"
        i += 1
    d.mkdir(parents=True)
    return d


# ------------------------------------------------------------------ summary.json
def _clean(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    return x


def summary(ev: Evolution, metrics: dict) -> dict:
    """The contents of summary.json after a generation."""
    best = metrics["best"]
    return _clean({
        "generation": metrics["generation"], "generations": ev.cfg.generations,
        "scenario": ev.cfg.scenario, "objective": ev.cfg.objective,
        "best_fitness": best["fitness"], "best_generation": best["generation"],
        "team_cost": best["cost"], "budget": ev.cfg.budget, "num_species": best["species"],
        "niches": best.get("niches"),
        "deliveries": best["deliveries"],
        "deliveries_individual": best["deliveries_individual"],
        "deliveries_collab": best["deliveries_collab"], "energy_used": best["energy_used"],
        "species_in_population": metrics["species/count"],
        "device": str(ev.ctx.device), "tick": ev.ctx.tick_mode,
        "designs": best["designs"],
        "last_generation": {k: v for k, v in metrics.items()
                            if "/" in k and isinstance(v, (int, float))},
    })


class SummaryReporter:
    """Rewrites summary.json (atomically) after every generation and appends the generation's
    best team to teams.jsonl (one JSON object per line)."""

    def __init__(self, run_dir: Path):
        self.path = Path(run_dir) / SUMMARY_FILE
        self.teams = Path(run_dir) / TEAMS_FILE

    def on_start(self, ev: Evolution) -> None:
        pass

    def on_generation(self, ev: Evolution, metrics: dict) -> None:
        atomic_write_bytes(self.path, json.dumps(summary(ev, metrics), indent=2).encode())
        with open(self.teams, "a") as f:
            f.write(json.dumps(_clean(metrics["team"])) + "\n")

    def on_end(self, ev: Evolution) -> None:
        pass


class CheckpointReporter:
    """Writes checkpoint.pt every `every` generations and at the end."""

    def __init__(self, run_dir: Path, every: int):
        self.run_dir, self.every = Path(run_dir), max(1, every)

    def on_start(self, ev: Evolution) -> None:
        pass

    def on_generation(self, ev: Evolution, metrics: dict) -> None:
        if ev.state.generation % self.every == 0:
            save_checkpoint(self.run_dir, ev)

    def on_end(self, ev: Evolution) -> None:
        save_checkpoint(self.run_dir, ev)


def generation_team(run_dir: Path, generation: int) -> dict:
    """The best team of one generation, from teams.jsonl (the last record wins after a resume)."""
    path = Path(run_dir) / TEAMS_FILE
    if not path.is_file():
        raise RunError(f"{run_dir} has no {TEAMS_FILE}")
    found = None
    for line in path.read_text().splitlines():
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line cut short by an interruption
        if rec.get("generation") == generation:
            found = rec
    if found is None:
        raise RunError(f"{run_dir} has no record of generation {generation}")
    return found


def run(ev: Evolution, run_dir: Path, reporters: Iterable[Reporter],
        on_interrupt: Callable[[Path], None] | None = None) -> Evolution:
    """Run generations until the configured total; Ctrl-C checkpoints the last finished one."""
    reporters = list(reporters)
    for r in reporters:
        r.on_start(ev)
    try:
        while not ev.done:
            metrics = ev.step()
            for r in reporters:
                r.on_generation(ev, metrics)
    except KeyboardInterrupt:
        path = save_checkpoint(run_dir, ev)
        if on_interrupt:
            on_interrupt(path)
        raise
    for r in reporters:
        r.on_end(ev)
    return ev
