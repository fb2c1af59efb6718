"""What the commands of the command line share: its consoles, one-line errors, path options
(`cli_output`), the progress line and a run executed under it (`execute`, here: its reporters,
and the line a stopped or failed run prints, `stop_lines`), the best team's table
(`team_table`), and the thread and Ray options of a run (`process_options`). Every public name is
importable from here."""

from __future__ import annotations

import sys
import threading
from contextlib import contextmanager
from pathlib import Path

import typer
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Column

from . import session
from .cli_output import MAX_PATH, Failed, check_path, console, err, fail, os_fail
from .process_options import (
    THREADS_HELP,
    attach_shards,
    eval_shards_option,
    need_ray,
    print_shard_traffic,
    set_threads_option,
)
from .reporter import Reporter
from .signals import TERMINATED, deferred_signals, terminate_as_interrupt
from .stop_lines import (
    Where,
    checkpoint_words,
    generations_done,
    last_checkpoint,
    stop_line,
    stopped,
)
from .team_table import best_interval, print_team

__all__ = [
    "MAX_PATH",
    "NARROW",
    "THREADS_HELP",
    "Failed",
    "ProgressReporter",
    "Where",
    "attach_shards",
    "best_interval",
    "check_path",
    "checkpoint_words",
    "close_writers",
    "console",
    "err",
    "eval_shards_option",
    "execute",
    "fail",
    "generations_done",
    "last_checkpoint",
    "need_ray",
    "os_fail",
    "print_shard_traffic",
    "print_team",
    "quiet_thread_os_errors",
    "set_threads_option",
    "stop_line",
    "stopped",
]


#: Below this many columns the progress line drops its bar and elapsed time.
NARROW = 60


class _FittedProgress(Progress):
    """A progress line that fits the window: the essential fields first (done count, time
    left), then the bar and elapsed time when there is room, then the generation's figures, cut
    with an ellipsis at the right edge. The columns are chosen at each refresh, so a resized
    window keeps the count and the time left in view."""

    def __init__(self, console: Console):
        self.wide = [
            TextColumn("done"),
            MofNCompleteColumn(),
            TextColumn("left"),
            TimeRemainingColumn(),
            BarColumn(bar_width=20),
            TimeElapsedColumn(),
        ]
        self.narrow = self.wide[:4]
        text = TextColumn(
            "{task.description}", table_column=Column(no_wrap=True, overflow="ellipsis", ratio=1)
        )
        self.wide.append(text)
        self.narrow.append(text)
        super().__init__(*self.wide, console=console, expand=True)

    def make_tasks_table(self, tasks):
        live = getattr(self, "live", None)  # None while Progress is being made
        if live is not None:
            self.columns = tuple(self.wide if live.console.width >= NARROW else self.narrow)
        return super().make_tasks_table(tasks)


class ProgressReporter(Reporter):
    """Rich progress line on a terminal (`out`, default the command line's console); a plain
    line every few generations otherwise, with the elapsed and remaining time (`eta.Eta`)."""

    def __init__(self, total: int, start: int, every: int, out: Console | None = None):
        from .eta import Eta

        self.tty = sys.stdout.isatty() if out is None else out.is_terminal
        self.every = every
        self.eta = Eta(total, start)
        self.bar = None
        if self.tty:
            self.bar = _FittedProgress(out if out is not None else console)
            self.task = self.bar.add_task("", total=total, completed=start)

    def on_start(self, ev) -> None:
        self.eta.restart()
        if self.bar:
            self.bar.start()

    def on_generation(self, ev, r) -> None:
        # generations are numbered from 0 (summary.json, teams.jsonl, TensorBoard steps); the
        # count "done" is how many have finished: generation g is the (g + 1)-th
        team = r.team
        # with re-evaluation, both are re-evaluated means (the best team's never below)
        this = team["reeval"]["mean"] if "reeval" in team else team["fitness"]
        text = (
            f"generation {r.generation}  best team {r.best['fitness']:.1f} "
            f"(this generation {this:.1f})  species {r.num_species}  "
            f"team {team['species']} sp, {team['niches']} niches, "
            f"${team['cost']:.0f}  {r.seconds:.2f}s/gen"
        )
        if self.bar:
            self.bar.update(self.task, completed=ev.state.generation, description=text)
        elif r.generation % self.every == 0 or ev.done:
            done = ev.state.generation
            print(f"done {done}/{ev.cfg.generations}  {self.eta.text(done)}  {text}", flush=True)

    def on_end(self, ev) -> None:
        self.stop()

    def stop(self) -> None:
        if self.bar:
            self.bar.stop()
            self.bar = None


def execute(
    ev,
    run_dir: Path,
    checkpoint_every: int,
    log_every: int,
    render_every: int = 0,
    saved: int | None = None,
    again: str | None = None,
    figure_every: int = 50,
    where: Where | None = None,
    wandb_project: str | None = None,
    snapshot_every: int = 0,
    bounds: session.Bounds | None = None,
    keep_checkpoints: int = 0,
    wandb_init: dict | None = None,
) -> None:
    """Run `ev` to its last generation with progress, summary, TensorBoard and checkpoints
    (and Weights & Biases with `wandb_project`, `wandb_init` more `wandb.init` keywords).
    Ctrl-C and SIGTERM write the checkpoint of the last finished generation (exit 130, 143). A
    failed write (a full disk: OSError from the checkpoint, summary.json, teams.jsonl or
    TensorBoard) ends the run with a one-line error that names the last checkpointed generation
    and how to continue (exit 2); the checkpoint on disk is the last complete one. `saved` is the
    generation of the checkpoint the run resumed from; `again` is the command to continue with
    (default: swarmcode-torch evolve --resume RUN_DIR); `snapshot_every`, `keep_checkpoints`,
    `bounds`: as `session.file_reporters` and `session.run` take them."""
    from .distributed import ShardError
    from .files import RunError

    again = again or f"swarmcode-torch evolve --resume {run_dir}"
    writers = session.file_reporters(
        run_dir,
        checkpoint_every,
        render_every,
        figure_every,
        saved=saved,
        snapshot_every=snapshot_every,
        keep_checkpoints=keep_checkpoints,
    )
    checkpoints = writers[-1]
    extra: list = []
    if wandb_project is not None:  # after the checkpoints: outside the step
        from .reporting import WandbReporter

        extra.append(WandbReporter(wandb_project, run_dir, render_every, **(wandb_init or {})))
    if where is not None:
        where.run_dir, where.checkpoints, where.again = run_dir, checkpoints, again
    reporters: list = []
    terminated: list[int] = []
    progress = None
    try:
        progress = ProgressReporter(ev.cfg.generations, ev.state.generation, log_every)
        reporters = [progress, *writers, *extra]
        with quiet_thread_os_errors():
            with terminate_as_interrupt() as terminated:
                session.run(ev, run_dir, reporters, bounds=bounds)
    except KeyboardInterrupt:
        with deferred_signals(deliver=False):  # the writers close whole (TensorBoard's thread)
            if progress is not None:
                progress.stop()
            close_writers(reporters)
        stopped = bool(terminated or TERMINATED)  # SIGTERM here or before the run loop
        err.print(
            stop_line(
                "Terminated" if stopped else "Interrupted", run_dir, checkpoints.saved, again
            ),
            markup=False,
            highlight=False,
            soft_wrap=True,
        )
        raise typer.Exit(code=143 if stopped else 130) from None
    except (RunError, OSError, ShardError) as e:
        if progress is not None:
            progress.stop()
        close_writers(reporters)
        _failed(e, ev.state.generation, run_dir, checkpoints.saved, again)
    progress.stop()


def _failed(e: Exception, generations: int, run_dir: Path, saved: int | None, again: str):
    """The one-line error of a run that failed after `generations` generations: a run directory
    that cannot be used (RunError), a failed write (OSError) or a failed evaluation shard; what
    the checkpoint file holds and how to continue."""
    from .distributed import ShardError
    from .files import RunError, os_error_text

    if isinstance(e, RunError):
        fail(f"{e}; {last_checkpoint(saved)}")
    if isinstance(e, ShardError):
        fail(
            f"{e} after {generations} generations; {last_checkpoint(saved)} "
            f"({run_dir / 'checkpoint.pt'}); continue with: {again}"
        )
    assert isinstance(e, OSError)
    what = f"writing the run's files failed after {generations} generations ({os_error_text(e)})"
    if saved is None:
        fail(
            f"{what}; no checkpoint was written yet: free space or fix the cause, then start "
            "the run again"
        )
    fail(
        f"{what}; {last_checkpoint(saved)} "
        f"({run_dir / 'checkpoint.pt'}); free space or fix the cause, then continue with: "
        f"{again}"
    )


def close_writers(reporters) -> None:
    """Stop the TensorBoard writer threads of a failed run (their errors are already reported)."""
    for r in reporters:
        writer = getattr(r, "writer", None)
        if writer is not None:
            try:
                writer.close()
                r.writer = None
            except Exception:  # noqa: BLE001 - the run already failed; this is cleanup
                pass


@contextmanager
def quiet_thread_os_errors():
    """Within the block an OSError in a background thread (TensorBoard's writer on a full disk)
    prints no traceback: the writer re-raises it in the run, which reports it in one line."""
    previous = threading.excepthook

    def hook(args):
        if not issubclass(args.exc_type, OSError):
            previous(args)

    threading.excepthook = hook
    try:
        yield
    finally:
        threading.excepthook = previous
