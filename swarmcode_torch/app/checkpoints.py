"""Checkpoints: written atomically with the digests of the run's copies, read back without
running code, loaded with the run's config and scenario checked against them, and resumed;
`CheckpointReporter` writes them during a run."""

from __future__ import annotations

import hashlib
import io
import os
import pickle
from pathlib import Path

import torch

from ..coevo.config import SwarmCoDeConfig, with_overrides
from ..coevo.evaluation import score_fn_name
from ..coevo.evolve import Evolution, GenerationResult
from ..sim.scenario import Scenario
from .files import (CHECKPOINT_FILE, CONFIG_FILE, HARDWARE_COPY, METRICS_FILE, SCENARIO_COPY,
                    RunError, atomic_write_bytes, open_nofollow, read_file_bytes, refuse_links)
from .runconfig import check_config, config_differences, config_from_dict, read_config, run_scenario

def copy_digests(run_dir: Path) -> dict[str, str]:
    """sha256 of the run's scenario.toml and hardware.toml copies (those it has): a checkpoint
    keeps them ("run_files"), so that a resume notices a copy edited since."""
    out = {}
    for name in (SCENARIO_COPY, HARDWARE_COPY):
        path = Path(run_dir) / name
        if path.is_file() and not path.is_symlink():
            out[name] = hashlib.sha256(read_file_bytes(path)).hexdigest()
    return out


def check_copies(run_dir: Path, d: dict) -> None:
    """RunError naming a scenario.toml or hardware.toml copy whose bytes are not those the
    checkpoint `d` recorded (edited since the run started; a checkpoint without "run_files",
    written before they were recorded, is not checked)."""
    saved = d.get("run_files")
    if not isinstance(saved, dict):
        return
    now = copy_digests(run_dir)
    for name in (SCENARIO_COPY, HARDWARE_COPY):
        if saved.get(name) != now.get(name):
            state = "is missing" if name not in now else "was changed"
            raise RunError(f"{Path(run_dir) / name} {state} since the run started (its sha256 "
                           f"is not the one {CHECKPOINT_FILE} recorded); the run computes with "
                           "its own copy: restore it, or start a new run")


def save_checkpoint(run_dir: Path, ev: Evolution) -> Path:
    buf = io.BytesIO()
    torch.save({**ev.state_dict(), "run_files": copy_digests(run_dir)}, buf)
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
        with os.fdopen(open_nofollow(path, os.O_RDONLY), "rb") as f:   # never through a link
            d = torch.load(f, map_location="cpu", weights_only=True)
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
    if not path.is_file() and not path.is_symlink():
        raise RunError(f"{run_dir} has no {CHECKPOINT_FILE} to resume from")
    return read_checkpoint(path)


def load_run(run_dir: Path) -> tuple[SwarmCoDeConfig, dict, Scenario]:
    """The config, checkpoint and scenario of a run directory, checked against each other:
    config.toml must agree with the config saved in the checkpoint in every key but generations
    and device (RunError otherwise); the scenario is built with the run's own catalog."""
    run_dir = Path(run_dir)
    refuse_links(run_dir)
    cfg = read_config(run_dir)
    d = load_checkpoint(run_dir)
    scenario = run_scenario(run_dir, cfg)       # a damaged copy: the file and field named
    check_copies(run_dir, d)
    saved = config_from_dict(d["config"], f"{run_dir / CHECKPOINT_FILE} (its config)")
    diff = config_differences(cfg, saved, scenario)
    if diff:
        raise RunError(f"{run_dir / CONFIG_FILE} does not match the config saved in "
                       f"{CHECKPOINT_FILE} (differing keys: {', '.join(diff)}); restore "
                       f"{CONFIG_FILE} or start a new run")
    metrics = run_dir / METRICS_FILE
    if metrics.exists() or metrics.is_symlink():
        from .reporting import read_metrics_csv
        read_metrics_csv(metrics, raw=True)      # a header a resume would lose rows under
    return cfg, d, scenario


def same_function(recorded: str, given: str) -> bool:
    """Whether a user fitness function named `given` ("module.qualname", `score_fn_name`) is the
    one a run recorded: the same name, or the same qualified name where one of the two ran as a
    script or notebook (module `__main__`) and the other was imported."""
    if recorded == given:
        return True
    main = "__main__."
    for a, b in ((recorded, given), (given, recorded)):
        if a.startswith(main) and not b.startswith(main) and b.endswith("." + a[len(main):]):
            return True
    return False


def resume(run_dir: Path, generations: int | None = None, device: str | None = None,
           loaded: tuple[SwarmCoDeConfig, dict, Scenario] | None = None,
           fitness=None) -> Evolution:
    """The run in `run_dir`, continued from its checkpoint with its saved config and its own
    copy of the scenario (`load_run`; `loaded` is what `load_run` returned, if it was called).
    `fitness`: the user fitness function of a run started with one (`api.evolve(fitness=)`),
    which a run directory records by name only; RunError without it, or with one for a run
    scored by the built-in fitness."""
    run_dir = Path(run_dir)
    cfg, d, scenario = loaded or load_run(run_dir)
    if cfg.fitness_function is not None and fitness is None:
        raise RunError(f"{run_dir} was scored by a custom fitness function "
                       f"({cfg.fitness_function}): resume it from Python with the same "
                       "function, swarmcode_torch.resume(run_dir, fitness=fn)")
    if cfg.fitness_function is None and fitness is not None:
        raise RunError(f"{run_dir} was scored by the built-in fitness; a resume cannot change "
                       "its fitness function (start a new run with fitness=fn)")
    if cfg.fitness_function is not None and not same_function(cfg.fitness_function,
                                                               score_fn_name(fitness)):
        raise RunError(f"{run_dir} was scored by {cfg.fitness_function}, not by "
                       f"{score_fn_name(fitness)}: a resume cannot change its fitness function "
                       f"(resume it with {cfg.fitness_function}, or start a new run with "
                       "fitness=fn)")
    cfg = with_overrides(cfg, generations=generations, device=device)
    check_config(cfg, scenario)
    try:                           # the run keeps the scenario it names; it runs on its copy
        return Evolution.from_checkpoint(d, cfg, fitness, scenario)
    except ValueError as e:
        raise RunError(f"{run_dir / CHECKPOINT_FILE} does not fit the run's config: {e}") from None
    except (KeyError, TypeError, RuntimeError, IndexError) as e:
        raise RunError(f"checkpoint in {run_dir} is incompatible ({type(e).__name__}: {e})") from None


class CheckpointReporter:
    """Writes checkpoint.pt at the start of a new run (generation 0, so that a run stopped
    before its first periodic checkpoint can still be resumed), every `every` generations and
    after the last one (as part of that generation's step: `run` writes the records of a
    generation, then its checkpoint, with signals held). `saved` is the generation of the
    checkpoint on disk (None: none yet)."""

    def __init__(self, run_dir: Path, every: int):
        self.run_dir, self.every = Path(run_dir), max(1, every)
        self.saved: int | None = None

    def on_start(self, ev: Evolution) -> None:
        path = self.run_dir / CHECKPOINT_FILE
        if path.exists() or path.is_symlink():
            self.saved = ev.state.generation        # resumed from it
        else:
            self._save(ev)

    def _save(self, ev: Evolution) -> None:
        save_checkpoint(self.run_dir, ev)
        self.saved = ev.state.generation

    def save_state(self, ev: Evolution) -> None:
        """The checkpoint of `ev`'s state, unless the file holds that generation already."""
        if self.saved != ev.state.generation:
            self._save(ev)

    def on_generation(self, ev: Evolution, result: GenerationResult) -> None:
        if ev.state.generation % self.every == 0 or ev.done:
            self._save(ev)

    def on_end(self, ev: Evolution) -> None:
        self.save_state(ev)
