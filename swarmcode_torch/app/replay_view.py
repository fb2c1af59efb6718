"""What the `replay` command shows while it works: a Rich progress bar (on the error console,
gone when done, nothing off a terminal) with one line per stage: the ticks of each team
recorded, the frames of a GIF drawn. `evaluate` shows its stages on the same bar
(`stage_progress`)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
)

from .episodes import ProgressFn
from .terminal import err

_STAGES = {
    "ticks": "recording the ticks",
    "focal ticks": "recording the focal team",
    "baseline ticks": "recording the baseline team",
    "frames": "drawing the frames",
}


@contextmanager
def stage_progress(labels: dict[str, str] | None = None) -> Iterator[ProgressFn]:
    """A `progress(stage, done, total)` drawn as a Rich bar, a line per stage, labelled as
    `labels` names it (the stage's own name otherwise)."""
    labels = labels or {}
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(bar_width=30),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=err,
        transient=True,
        disable=not err.is_terminal,
    ) as bar:
        tasks: dict[str, TaskID] = {}

        def progress(stage: str, done: int, total: int) -> None:
            if stage not in tasks:
                tasks[stage] = bar.add_task(labels.get(stage, stage), total=total)
            bar.update(tasks[stage], completed=done, total=total)

        yield progress


def replay_progress():
    """A `progress(stage, done, total)` for `analysis.replay_run`, drawn as a Rich bar."""
    return stage_progress(_STAGES)
