"""What `swarmcode-torch inspect` prints besides the best team: a sweep directory's table and
runs, a branched run's parent and an early stop, and the package classes each design lifts."""

from __future__ import annotations

from pathlib import Path

from .terminal import console, fail, generations_done, os_fail


def print_lineage(run_dir: Path) -> None:
    """inspect: the run a branched run started from, and why a run stopped early."""
    from .runconfig import read_parent
    from .summary import read_summary

    parent = read_parent(run_dir)
    if parent is not None:
        console.print(
            f"Branched from {parent.get('run')} at generation "
            f"{parent.get('generation')} ({parent.get('checkpoint')})",
            markup=False,
            highlight=False,
            soft_wrap=True,
        )
    stop = read_summary(run_dir).get("stop")
    if isinstance(stop, dict) and stop.get("reason") in ("max_time", "patience", "callback"):
        done = stop.get("generation")  # generations finished: a count (`session.Bounds`)
        after = f" after {generations_done(done)}" if isinstance(done, int) else ""
        console.print(
            f"Stopped early by {stop['reason']}{after}; it can be continued with evolve --resume",
            markup=False,
            highlight=False,
        )


def inspect_sweep(path: Path) -> bool:
    """Print the table and the runs of a sweep directory; False when `path` is none."""
    from .files import TABLE_CSV, TABLE_MD, RunError
    from .sweep import sweep_contents

    try:
        sweep = sweep_contents(path)
    except RunError as e:
        fail(str(e))
    except OSError as e:
        os_fail(e, f"{path} cannot be read")
    if sweep is None:
        return False
    if sweep.table is not None:
        console.print(sweep.table, markup=False, highlight=False, soft_wrap=True)
        console.print(
            f"Table: {path / TABLE_MD}, {path / TABLE_CSV}",
            markup=False,
            highlight=False,
            soft_wrap=True,
        )
    else:
        console.print(
            f"{path} is a sweep without a table yet: run its sweep command again with "
            f"--out {path} to finish it and write the table",
            markup=False,
            highlight=False,
            soft_wrap=True,
        )
    console.print(f"Runs ({len(sweep.runs)}):", highlight=False)
    for name, done, total in sweep.runs:
        state = (
            "no generation recorded"
            if done is None
            else f"{done}/{total} generations"
            if total is not None
            else f"{done} generations"
        )
        console.print(f"  {name}: {state}", markup=False, highlight=False, soft_wrap=True)
    if sweep.runs:
        console.print(
            f"Inspect a run: swarmcode-torch inspect {path / sweep.runs[0][0]}",
            markup=False,
            highlight=False,
            soft_wrap=True,
        )
    return True


def capabilities(run_dir: Path, designs: list[dict]):
    """(package class labels, per design the classes it lifts), or None without a scenario; a
    one-line error for a recorded capability naming a class the scenario has not."""
    from .analysis import design_capabilities
    from .files import SUMMARY_FILE
    from .runs import RunError, read_config, run_scenario
    from .summary import check_capability_classes

    try:
        scenario = run_scenario(run_dir, read_config(run_dir))
    except (RunError, ValueError):
        return None
    try:
        check_capability_classes(designs, len(scenario.packages), str(run_dir / SUMMARY_FILE))
    except RunError as e:
        fail(str(e))
    try:
        return [c.label for c in scenario.packages], design_capabilities(designs, scenario)
    except (RunError, ValueError):
        return None
