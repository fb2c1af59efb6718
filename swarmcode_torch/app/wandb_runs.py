"""What Weights & Biases gets besides a run's scalars: its files as an artifact at the end of
the run (`log_run_files`), and the group and tags that gather a sweep's runs (`sweep_init`).
`report_wandb.WandbReporter` and the sweep (`sweep_run`) call them; docs/TENSORBOARD.md
describes what is logged."""

from __future__ import annotations

import re
from pathlib import Path

from .files import CHECKPOINT_FILE, REPLAY_FILE
from .replay_page import HTML_FILE

#: The files of a run directory logged as its artifact at the end of the run, when they exist:
#: the checkpoint (the run's whole state: resume, replay, inspect it from W&B), and the replays
#: `replay` writes by default (the page, the GIF).
ARTIFACT_FILES = (CHECKPOINT_FILE, HTML_FILE, REPLAY_FILE)
#: The artifact type of a run's files.
ARTIFACT_TYPE = "swarmcode-run"


def artifact_name(run_dir: Path) -> str:
    """A W&B artifact name for a run directory (letters, digits, '-', '_', '.'; at most 128)."""
    return re.sub(r"[^A-Za-z0-9_.-]", "-", f"run-{Path(run_dir).name}")[:128]


def log_run_files(wandb, run, run_dir: Path) -> list[str]:
    """Log the `ARTIFACT_FILES` that exist in `run_dir` (regular files, not links) as one
    artifact of `run` (a new version of it on each resume); the names logged ([] logs nothing)."""
    names = [n for n in ARTIFACT_FILES if (Path(run_dir) / n).is_file()]
    names = [n for n in names if not (Path(run_dir) / n).is_symlink()]
    if not names:
        return []
    art = wandb.Artifact(
        artifact_name(run_dir),
        type=ARTIFACT_TYPE,
        description=f"checkpoint and replays of the run directory {Path(run_dir).name}",
    )
    for n in names:
        art.add_file(str(Path(run_dir) / n), name=n)
    run.log_artifact(art)
    return names


def sweep_init(sweep_dir: Path, budget: float, seed: int) -> dict:
    """The `wandb.init` keywords of one run of a sweep: its group, the sweep directory's name
    (so W&B shows the sweep's runs together), and tags for the sweep, its budget and its seed."""
    return {
        "group": Path(sweep_dir).name[:128],
        "tags": ["sweep", f"budget-{budget:g}", f"seed-{seed}"],
        "job_type": "sweep-run",
    }
