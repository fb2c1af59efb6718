"""One run of a sweep and the sweep's progress over its runs: what the sweep runs in this
process (`sweep_run`) and what each Ray task runs (`sweep_ray`)."""

from __future__ import annotations

from contextlib import ExitStack
from pathlib import Path

from rich.markup import escape

from ..sim.scenario import ScenarioError
from . import session
from .terminal import console, execute, fail, os_fail


def sweep_progress(plans):
    """The sweep's progress (`sweep_grid.SweepProgress`) over its runs (`plan_sweep_run`'s):
    the generations each has left."""
    from .sweep_grid import SweepProgress

    return SweepProgress([max(0, cfg.generations - (done or 0)) for *_, cfg, _, done in plans])


def run_sweep_run(
    run_dir: Path,
    cfg,
    data: bytes,
    state: str,
    checkpoint_every: int,
    log_every: int,
    again: str,
    wb: tuple[str, dict] | None = None,
) -> None:
    """One run of a sweep, started (`state` 'new': its config and `data` checked by the sweep)
    or resumed through `session`, then run with the command line's progress and messages (and
    logged to W&B with `wb`, `sweep_wandb`'s)."""
    from .files import RunError

    def make_dir(ev) -> Path:
        run_dir.mkdir(exist_ok=True)
        return run_dir

    with ExitStack() as stack:
        try:
            if state == "resume":
                start = session.start_resume(stack, run_dir, generations=cfg.generations)
            else:  # a config error leaves no directory behind
                start = session.start_new(stack, cfg, make_dir, data=data)
            ev, saved = start.ev, start.saved
        except (ScenarioError, RunError, ValueError) as e:
            fail(str(e))
        except OSError as e:
            os_fail(e, f"{run_dir}: cannot start the run")
        console.print(
            f"[bold]{escape(run_dir.name)}[/]: generation {ev.state.generation} -> "
            f"{cfg.generations}",
            soft_wrap=True,
        )
        execute(
            ev,
            run_dir,
            checkpoint_every,
            log_every,
            saved=saved,
            again=again,
            wandb_project=wb[0] if wb else None,
            wandb_init=wb[1] if wb else None,
        )
