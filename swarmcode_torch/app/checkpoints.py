"""Checkpoints: the algorithm's state and, beside it, the application's record of the run
(`run_record`, the "app" table) written atomically with the digests of the run's copies, read
back without running code, loaded with the run's config and scenario checked against them, and
resumed; `CheckpointReporter` writes them during a run."""

from __future__ import annotations

import hashlib
import io
import re
from dataclasses import dataclass
from pathlib import Path

import torch

from ..coevo.ask_tell import Evolution
from ..coevo.config import SwarmCoDeConfig, with_overrides
from ..coevo.evaluation import score_fn_name
from ..coevo.evolve import GenerationResult
from ..sim.scenario import Scenario
from .checkpoint_read import read_checkpoint
from .files import (
    CHECKPOINT_FILE,
    CONFIG_FILE,
    HARDWARE_COPY,
    METRICS_FILE,
    SCENARIO_COPY,
    SNAPSHOT_DIR,
    RunError,
    atomic_write_bytes,
    numbered_files,
    own_folder,
    read_file_bytes,
    refuse_links,
)
from .migrations import check_runnable
from .reporter import Reporter
from .run_record import APP_KEY, app_record, restore
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
            raise RunError(
                f"{Path(run_dir) / name} {state} since the run started (its sha256 "
                f"is not the one {CHECKPOINT_FILE} recorded); the run computes with "
                "its own copy: restore it, or start a new run"
            )


def save_checkpoint(run_dir: Path, ev: Evolution, path: Path | None = None) -> Path:
    """The checkpoint of `ev`'s state, with the application's record of the run beside it
    ("app") and the digests of the run's copies, written atomically to `path` (default: the
    run's checkpoint.pt; a snapshot's path, `snapshot_path`)."""
    buf = io.BytesIO()
    d = {
        **ev.state_dict(),
        APP_KEY: app_record(ev).state_dict(),
        "run_files": copy_digests(run_dir),
    }
    torch.save(d, buf)
    path = Path(run_dir) / CHECKPOINT_FILE if path is None else Path(path)
    atomic_write_bytes(path, buf.getvalue())
    return path


# ------------------------------------------------------------------ snapshots
_SNAPSHOT_NAME = re.compile(r"^generation-(\d{6,})\.pt$")


def snapshot_path(run_dir: Path, generation: int) -> Path:
    """Where a run keeps its snapshot of `generation`: snapshots/generation-000100.pt."""
    return Path(run_dir) / SNAPSHOT_DIR / f"generation-{generation:06d}.pt"


def snapshot_folder(run_dir: Path, make: bool = False) -> Path:
    """The run's snapshots folder (made when `make`); RunError when it is a link or not a
    folder (a run reads and writes only its own files)."""
    return own_folder(Path(run_dir) / SNAPSHOT_DIR, "snapshots", make)


def list_snapshots(run_dir: Path) -> dict[int, Path]:
    """generation -> the run's snapshot file of it, oldest first ({} without snapshots)."""
    return numbered_files(snapshot_folder(run_dir), _SNAPSHOT_NAME)


def load_checkpoint(run_dir: Path) -> dict:
    """The checkpoint of a run directory (see `read_checkpoint`)."""
    path = Path(run_dir) / CHECKPOINT_FILE
    if not path.exists() and not path.is_symlink():
        raise RunError(f"{run_dir} has no {CHECKPOINT_FILE} to resume from")
    return read_checkpoint(path)


def _run_matches(
    run_dir: Path, cfg: SwarmCoDeConfig, d: dict, path: Path, named, advice: str = ""
) -> Scenario:
    """The run's scenario (built with its own catalog; a damaged copy: the file and field
    named), once its copies are those the checkpoint `d` (read from `path`) recorded and its
    config.toml `cfg` agrees with the config saved in `d` in every key but generations and
    device; RunError otherwise, naming the checkpoint as `named`, then `advice`."""
    scenario = run_scenario(run_dir, cfg)
    check_copies(run_dir, d)
    saved = config_from_dict(d["config"], f"{path} (its config)")
    diff = config_differences(cfg, saved, scenario)
    if diff:
        raise RunError(
            f"{run_dir / CONFIG_FILE} does not match the config saved in {named} "
            f"(differing keys: {', '.join(diff)}){advice}"
        )
    return scenario


def load_run(run_dir: Path) -> tuple[SwarmCoDeConfig, dict, Scenario]:
    """The config, checkpoint and scenario of a run directory, checked against each other:
    config.toml must agree with the config saved in the checkpoint in every key but generations
    and device (RunError otherwise); the scenario is built with the run's own catalog."""
    run_dir = Path(run_dir)
    refuse_links(run_dir)
    cfg = read_config(run_dir)
    d = load_checkpoint(run_dir)
    scenario = _run_matches(
        run_dir,
        cfg,
        d,
        run_dir / CHECKPOINT_FILE,
        CHECKPOINT_FILE,
        f"; restore {CONFIG_FILE} or start a new run",
    )
    metrics = run_dir / METRICS_FILE
    if metrics.exists() or metrics.is_symlink():
        from .reporting import read_metrics_csv

        read_metrics_csv(metrics, raw=True)  # a header a resume would lose rows under
    return cfg, d, scenario


def evolution_from_checkpoint(
    d: dict, cfg: SwarmCoDeConfig, fitness=None, scenario: Scenario | None = None, checked=False
) -> Evolution:
    """The `Evolution` of checkpoint `d` (as `read_checkpoint` returns it) with `cfg`, and the
    application's record of the run it saved (`run_record.restore`); ValueError where the
    algorithm's state does not fit `cfg`."""
    return restore(Evolution.from_checkpoint(d, cfg, fitness, scenario, checked=checked), d)


def same_function(recorded: str, given: str) -> bool:
    """Whether a user fitness function named `given` ("module.qualname", `score_fn_name`) is the
    one a run recorded: the same name, or the same qualified name where one of the two ran as a
    script or notebook (module `__main__`) and the other was imported."""
    if recorded == given:
        return True
    # a lambda or local function carries a hash of its code, which must match too (a run
    # recorded before the hash existed is matched by name, as it was then)
    (recorded, _, code_a), (given, _, code_b) = recorded.partition("#"), given.partition("#")
    if code_a and code_b and code_a != code_b:
        return False
    if recorded == given:
        return True
    main = "__main__."
    for a, b in ((recorded, given), (given, recorded)):
        if a.startswith(main) and not b.startswith(main) and b.endswith("." + a[len(main) :]):
            return True
    return False


def resume(
    run_dir: Path,
    generations: int | None = None,
    device: str | None = None,
    loaded: tuple[SwarmCoDeConfig, dict, Scenario] | None = None,
    fitness=None,
) -> Evolution:
    """The run in `run_dir`, continued from its checkpoint with its saved config and its own
    copy of the scenario (`load_run`; `loaded` is what `load_run` returned, if it was called).
    `fitness`: the user fitness function of a run started with one (`api.evolve(fitness=)`),
    which a run directory records by name only; RunError without it, or with one for a run
    scored by the built-in fitness."""
    run_dir = Path(run_dir)
    cfg, d, scenario = loaded or load_run(run_dir)
    if cfg.fitness_function is not None and fitness is None:
        raise RunError(
            f"{run_dir} was scored by a custom fitness function "
            f"({cfg.fitness_function}): resume it from Python with the same "
            "function, swarmcode_torch.resume(run_dir, fitness=fn)"
        )
    if cfg.fitness_function is None and fitness is not None:
        raise RunError(
            f"{run_dir} was scored by the built-in fitness; a resume cannot change "
            "its fitness function (start a new run with fitness=fn)"
        )
    if cfg.fitness_function is not None and not same_function(
        cfg.fitness_function, score_fn_name(fitness)
    ):
        raise RunError(
            f"{run_dir} was scored by {cfg.fitness_function}, not by "
            f"{score_fn_name(fitness)}: a resume cannot change its fitness function "
            f"(resume it with {cfg.fitness_function}, or start a new run with "
            "fitness=fn)"
        )
    check_runnable(d["config"], str(run_dir / CHECKPOINT_FILE))
    cfg = with_overrides(cfg, generations=generations, device=device)
    check_config(cfg, scenario)
    try:  # the run keeps the scenario it names; it runs on its copy
        return evolution_from_checkpoint(d, cfg, fitness, scenario, checked=True)
    except ValueError as e:
        raise RunError(f"{run_dir / CHECKPOINT_FILE} does not fit the run's config: {e}") from None
    except (KeyError, TypeError, RuntimeError, IndexError) as e:
        raise RunError(
            f"checkpoint in {run_dir} is incompatible ({type(e).__name__}: {e})"
        ) from None


@dataclass
class Branch:
    """What a new run branched from another starts from (`load_branch`): the parent's run
    directory, the generation and file of its snapshot, the parent's config, the checkpoint's
    contents, its scenario and the bytes of its scenario.toml and hardware.toml copies (None for
    a run made before runs kept them)."""

    run_dir: Path
    generation: int
    path: Path
    config: SwarmCoDeConfig
    checkpoint: dict
    scenario: Scenario
    scenario_bytes: bytes | None
    hardware_bytes: bytes | None

    @property
    def parent(self) -> dict:
        """The [parent] table of the new run's config.toml and its summary.json's "parent"."""
        return {
            "run": str(self.run_dir.absolute()),
            "generation": self.generation,
            "checkpoint": self.path.relative_to(self.run_dir).as_posix(),
        }


def parse_run_ref(text: str) -> tuple[Path, int | None]:
    """RUN[@GENERATION] -> (RUN, GENERATION or None): the part after the last "@" is a
    generation when it is a number (a run directory's name may hold an "@" too); ValueError
    for "RUN@" followed by something that is no generation >= 0."""
    head, sep, tail = text.rpartition("@")
    if not sep or not head:
        return Path(text), None
    if tail.isdigit() and tail.isascii():
        return Path(head), int(tail)
    if tail.strip("-").isdigit() or not tail:
        raise ValueError(f"{text}: the generation after @ must be an integer >= 0, got {tail!r}")
    return Path(text), None


def load_branch(run_dir: Path, generation: int | None = None) -> Branch:
    """The snapshot a new run branches from: the run's snapshot of `generation`
    (snapshots/generation-NNNNNN.pt, or checkpoint.pt when it holds that generation), or its
    latest checkpoint (`generation` None), checked as `load_run` checks a resume (the run's
    config, its copies, no links). RunError, one line: no run there, no such generation (the
    message lists those there are), a link, a damaged file."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunError(f"{run_dir} is not a run directory (no such directory)")
    refuse_links(run_dir)
    cfg = read_config(run_dir)
    latest = run_dir / CHECKPOINT_FILE
    if generation is None:
        if not latest.is_file() and not latest.is_symlink():
            raise RunError(f"{run_dir} has no {CHECKPOINT_FILE} to branch from")
        path = latest
        d = read_checkpoint(path)
    else:
        snaps = list_snapshots(run_dir)
        d = None
        if generation in snaps:
            path = snaps[generation]
        else:
            path = latest
            held = None
            if latest.is_file() and not latest.is_symlink():
                d = read_checkpoint(latest)
                held = d["generation"]
            if held != generation:
                have = ", ".join(map(str, snaps)) or "none"
                extra = (
                    f"; its {CHECKPOINT_FILE} holds generation {held}" if held is not None else ""
                )
                raise RunError(
                    f"{run_dir} has no snapshot of generation {generation} "
                    f"(snapshots of generations: {have}{extra})"
                )
        if d is None:
            d = read_checkpoint(path)
        if d["generation"] != generation:
            raise RunError(f"{path} holds generation {d['generation']}, not {generation}")
    scenario = _run_matches(run_dir, cfg, d, path, path)

    def copy(name: str) -> bytes | None:
        p = run_dir / name
        if not p.is_file() and not p.is_symlink():
            return None
        try:
            return read_file_bytes(p)
        except OSError as e:
            raise RunError(f"{p} cannot be read ({e.strerror or type(e).__name__})") from None

    return Branch(
        run_dir, d["generation"], path, cfg, d, scenario, copy(SCENARIO_COPY), copy(HARDWARE_COPY)
    )


class CheckpointReporter(Reporter):
    """Writes checkpoint.pt at the start of a new run (generation 0, so that a run stopped
    before its first periodic checkpoint can still be resumed), every `every` generations and
    after the last one (as part of that generation's step: `run` writes the records of a
    generation, then its checkpoint, with signals held); with `snapshot_every` N > 0 it also
    keeps a copy of the checkpoint of every N-th generation (`snapshot_path`:
    snapshots/generation-000100.pt), written the same way. `saved` is the generation of the
    checkpoint on disk (None: none yet)."""

    def __init__(self, run_dir: Path, every: int, snapshot_every: int = 0):
        self.run_dir, self.every = Path(run_dir), max(1, every)
        self.snapshot_every = max(0, snapshot_every)
        self.saved: int | None = None

    def on_start(self, ev: Evolution) -> None:
        if self.snapshot_every:
            snapshot_folder(self.run_dir, make=True)
        path = self.run_dir / CHECKPOINT_FILE
        if path.exists() or path.is_symlink():
            self.saved = ev.state.generation  # resumed from it
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
        g = ev.state.generation
        if self.snapshot_every and g % self.snapshot_every == 0:
            save_checkpoint(self.run_dir, ev, snapshot_path(self.run_dir, g))
        if g % self.every == 0 or ev.done:
            self._save(ev)

    def on_end(self, ev: Evolution) -> None:
        self.save_state(ev)
