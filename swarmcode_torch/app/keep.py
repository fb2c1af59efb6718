"""--keep-checkpoints K: besides checkpoint.pt (the latest, which resume reads), the last K
checkpoints as RUN_DIR/checkpoints/generation-NNNNNN.pt and the state that holds the run's best
team as RUN_DIR/checkpoints/best.pt (Lightning's save_top_k / save_last).

Each file is written whole (`checkpoints.save_checkpoint`: a temporary file renamed), the copy of
a generation when checkpoint.pt is written (every --checkpoint-every generations, at the end, on
a stop or an interrupt), best.pt after each generation whose best team is better than the run's
before it (the run's best team by its re-evaluated mean, `best_team.update`); then the oldest
generation files beyond K are removed."""

from __future__ import annotations

import re
from pathlib import Path

from ..coevo.evolve import Evolution, GenerationResult
from .checkpoints import CheckpointReporter, save_checkpoint
from .files import clean_temporary_files, numbered_files, own_folder
from .run_record import app_record

KEEP_DIR = "checkpoints"
BEST_FILE = "best.pt"
_KEPT = re.compile(r"^generation-(\d{6,})\.pt$")
_TARGETS = re.compile(r"^(generation-\d{6,}|best)\.pt$")


def keep_folder(run_dir: Path, make: bool = False) -> Path:
    """RUN_DIR/checkpoints (made when `make`); RunError when it is a link or not a folder."""
    return own_folder(Path(run_dir) / KEEP_DIR, "checkpoints", make)


def kept(run_dir: Path) -> dict[int, Path]:
    """generation -> the kept checkpoint of it, oldest first ({} without any)."""
    return numbered_files(keep_folder(run_dir), _KEPT, files_only=True)


def check_keep(keep, name: str = "keep_checkpoints") -> int:
    """`keep` as an integer >= 0 (0: keep none); ValueError, one line, naming `name`."""
    if not isinstance(keep, int) or isinstance(keep, bool) or keep < 0:
        raise ValueError(f"{name} must be an integer >= 0 (0: none kept), got {keep!r:.40}")
    return keep


def checkpoint_reporter(
    run_dir: Path, every: int, snapshot_every: int = 0, keep: int = 0
) -> CheckpointReporter:
    """The run's checkpoint writer: a `KeepingCheckpoints` with `keep` > 0, else the plain one."""
    if keep:
        return KeepingCheckpoints(run_dir, every, snapshot_every, keep)
    return CheckpointReporter(run_dir, every, snapshot_every)


class KeepingCheckpoints(CheckpointReporter):
    """`CheckpointReporter` that also keeps the last `keep` checkpoints and the best one
    (the module's docstring)."""

    def __init__(self, run_dir: Path, every: int, snapshot_every: int = 0, keep: int = 1):
        super().__init__(run_dir, every, snapshot_every)
        self.keep = check_keep(keep)
        self.best_generation: int | None = None

    def on_start(self, ev: Evolution) -> None:
        folder = keep_folder(self.run_dir, make=True)
        clean_temporary_files(folder, _TARGETS)
        best = app_record(ev).best
        self.best_generation = None if best is None else int(best["generation"])
        super().on_start(ev)

    def _save(self, ev: Evolution) -> None:
        super()._save(ev)
        g = ev.state.generation
        save_checkpoint(self.run_dir, ev, keep_folder(self.run_dir) / f"generation-{g:06d}.pt")
        old = list(kept(self.run_dir).items())
        for _, path in old[: max(0, len(old) - self.keep)]:
            path.unlink(missing_ok=True)

    def on_generation(self, ev: Evolution, result: GenerationResult) -> None:
        best = app_record(ev).best
        if best is not None and int(best["generation"]) != self.best_generation:
            save_checkpoint(self.run_dir, ev, keep_folder(self.run_dir) / BEST_FILE)
            self.best_generation = int(best["generation"])
        super().on_generation(ev, result)
