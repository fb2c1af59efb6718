"""The line an interrupted, terminated or failed run prints: where it stands (`Where`) and the
checkpoint its file really holds (`checkpoint_words`, `stop_line`, `stopped`); a count of
finished generations with their numbers (`generations_done`)."""

from __future__ import annotations

from pathlib import Path

import typer

from .cli_output import err
from .signals import TERMINATED


class Where:
    """Where an evolve command stands, for the line an interrupt prints: its run directory (None
    before one is made or locked), whether it resumes one, the generation its checkpoint file
    holds (`saved`; the `CheckpointReporter`'s once the run loop has it) and how to continue."""

    def __init__(self):
        self.run_dir: Path | None = None
        self.resuming = False
        self.saved: int | None = None
        self.checkpoints = None
        self.again: str | None = None

    def holds(self) -> int | None:
        return self.checkpoints.saved if self.checkpoints is not None else self.saved


def checkpoint_words(saved: int) -> str:
    """The checkpoint of a run that has finished `saved` generations (the checkpoint file's
    "generation" count), named as summary.json, teams.jsonl and TensorBoard number generations:
    from 0, so that its last finished generation is summary.json's "generation"."""
    if saved == 0:
        return "checkpoint before generation 0 (no generation finished yet)"
    done = "generation 0 finished" if saved == 1 else f"generations 0-{saved - 1} finished"
    return f"checkpoint after generation {saved - 1} ({done})"


def generations_done(done: int) -> str:
    """'3 generations (0-2)': how many generations finished, and their numbers, from 0 as
    summary.json, teams.jsonl and TensorBoard number them (never the count as a number)."""
    if done < 1:
        return "no generation"
    return "1 generation (generation 0)" if done == 1 else f"{done} generations (0-{done - 1})"


def last_checkpoint(saved: int | None) -> str:
    """'the last checkpoint ...' of a failed run (`checkpoint_words`), or that there is none."""
    if saved is None:
        return "no checkpoint was written yet"
    return f"the last {checkpoint_words(saved)}"


def stop_line(
    how: str, run_dir: Path | None, saved: int | None, again: str | None, resuming: bool = False
) -> str:
    """The line an interrupted run prints: the checkpoint its file really holds
    (`checkpoint_words`: the last finished generation, numbered as in summary.json), or that
    there is none."""
    if run_dir is None:
        return f"{how}: no run directory was made"
    if saved is None:
        if resuming:
            return f"{how} before the run resumed; {run_dir} is unchanged"
        return (
            f"{how}: no checkpoint was written yet, so {run_dir} holds no generation to "
            "continue from; start the run again"
        )
    again = again or f"swarmcode-torch evolve --resume {run_dir}"
    return f"{how}: {checkpoint_words(saved)} is in {run_dir}; continue with: {again}"


def stopped(where: Where, terminated: bool) -> None:
    terminated = terminated or bool(TERMINATED)
    how = "Terminated" if terminated else "Interrupted"
    err.print(
        stop_line(how, where.run_dir, where.holds(), where.again, where.resuming),
        markup=False,
        highlight=False,
        soft_wrap=True,
    )
    raise typer.Exit(code=143 if terminated else 130)
