"""What the commands of the command line share: its consoles, one-line errors, path options,
the progress line, a run executed under it (`execute`: its reporters, and the line a stopped or
failed run prints), the best team's table, and the Ray options of a run."""

from __future__ import annotations

import math
import sys
import threading
from contextlib import ExitStack, contextmanager
from pathlib import Path

import typer
from rich import box
from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Column, Table

from . import session
from .signals import TERMINATED, deferred_signals, terminate_as_interrupt

# off a terminal (logs, pipes) Rich would wrap at 80 columns; tables need a little more
console = Console(width=None if sys.stdout.isatty() else 120)
err = Console(stderr=True, width=None if sys.stderr.isatty() else 200)


class Failed(typer.Exit):
    """The exit (code 2) of `fail`; `message` is its line (a sweep's Ray task reports it)."""

    def __init__(self, message: str):
        super().__init__(code=2)
        self.message = message


def fail(msg: str) -> None:
    """Print a one-line error and exit non-zero. The message is printed as it is: brackets such
    as [low, high] or [[packages]] are not read as Rich markup; a newline inside it becomes a
    space, so the error stays on one line."""
    msg = " ".join(str(msg).split())
    err.print(f"[bold red]Error:[/] {escape(msg)}", highlight=False, soft_wrap=True)
    raise Failed(msg)


#: The longest path an option takes (PATH_MAX).
MAX_PATH = 4096


def check_path(value: str | None, option: str) -> Path | None:
    """An option's path, checked: not empty (an empty --logdir would write into the working
    directory; '.' says so), at most MAX_PATH characters, no NUL, and text that can be printed
    (bytes that are not UTF-8 reach Python as surrogates no message can print)."""
    if value is None:
        return None
    if not value.strip():
        fail(f"{option} is empty: give a directory ('.' for the working directory)")
    if len(value) > MAX_PATH or "\0" in value:
        fail(
            f"{option}: not a path ({len(value)} characters{', a NUL' if chr(0) in value else ''};"
            f" at most {MAX_PATH})"
        )
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        fail(
            f"{option}: the path {value.encode('utf-8', 'backslashreplace').decode()[:200]} "
            "is not UTF-8 text; rename it or give another"
        )
    return Path(value)


def os_fail(e: OSError, doing: str) -> None:
    from .files import os_error_text

    fail(f"{doing}: {os_error_text(e)}")


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


class ProgressReporter:
    """Rich progress line on a terminal (`out`, default the command line's console); a plain
    line every few generations otherwise."""

    def __init__(self, total: int, start: int, every: int, out: Console | None = None):
        self.tty = sys.stdout.isatty() if out is None else out.is_terminal
        self.every = every
        self.bar = None
        if self.tty:
            self.bar = _FittedProgress(out if out is not None else console)
            self.task = self.bar.add_task("", total=total, completed=start)

    def on_start(self, ev) -> None:
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
            print(f"done {ev.state.generation}/{ev.cfg.generations}  {text}", flush=True)

    def on_end(self, ev) -> None:
        self.stop()

    def stop(self) -> None:
        if self.bar:
            self.bar.stop()
            self.bar = None


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


def set_threads_option(threads: int | None) -> None:
    from ..sim.runtime import set_threads

    try:
        set_threads(threads)
    except ValueError as e:
        fail(f"--{e}")


def eval_shards_option(eval_workers: int, cpus: float | None, address: str | None):
    """(workers, CPUs per worker, address) of a sharded evaluation, or None for the evaluation
    in this process; a one-line error for bad values or Ray options without Ray."""
    if eval_workers < 1:
        fail(f"--eval-workers must be >= 1, got {eval_workers}")
    if eval_workers == 1 and address is None:
        if cpus is not None:
            fail(
                "--cpus-per-eval-worker is for evaluation shards on Ray: use it with "
                "--eval-workers N > 1 or --ray-address"
            )
        return None
    if cpus is not None and not (cpus > 0 and math.isfinite(cpus)):
        fail(f"--cpus-per-eval-worker must be a finite number > 0, got {cpus}")
    need_ray(f"--eval-workers {eval_workers}" if eval_workers > 1 else "--ray-address")
    return eval_workers, 1.0 if cpus is None else cpus, address


def need_ray(what: str) -> None:
    """A one-line error naming the extra to install when Ray is missing."""
    from .distributed import RayUnavailable, require_ray

    try:
        require_ray(what)
    except RayUnavailable as e:
        fail(str(e))


def attach_shards(stack: ExitStack, ev, workers: int, cpus: float, address: str | None) -> None:
    """Evaluate `ev`'s generations in shards on Ray actors until `stack` closes."""
    from .distributed import RayUnavailable, sharded_evaluation

    try:
        evaluator = stack.enter_context(sharded_evaluation(ev, workers, address, cpus))
    except RayUnavailable as e:
        fail(str(e))
    where = sorted(set(evaluator.where))
    console.print(
        f"Evaluation: {workers} shards on Ray actors ({escape('; '.join(where))})",
        highlight=False,
        soft_wrap=True,
    )


def print_shard_traffic(evaluator) -> None:
    stats = getattr(evaluator, "stats", None)
    if not stats:
        return
    n = len(stats)
    sent = sum(s["bytes_sent"] for s in stats) / n
    back = sum(s["bytes_received"] for s in stats) / n
    console.print(
        f"Evaluation shards: {sent / 1024:.1f} KiB sent and {back / 1024:.1f} KiB "
        f"received per generation (pickled, mean of {n} generations)",
        highlight=False,
        markup=False,
    )


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
) -> None:
    """Run `ev` to its last generation with progress, summary, TensorBoard and checkpoints
    (and Weights & Biases with `wandb_project`).
    Ctrl-C and SIGTERM write the checkpoint of the last finished generation (exit 130, 143). A
    failed write (a full disk: OSError from the checkpoint, summary.json, teams.jsonl or
    TensorBoard) ends the run with a one-line error that names the last checkpointed generation
    and how to continue (exit 2); the checkpoint on disk is the last complete one. `saved` is the
    generation of the checkpoint the run resumed from; `again` is the command to continue with
    (default: swarmcode-torch evolve --resume RUN_DIR); `snapshot_every`, `bounds`: as
    `session.file_reporters` and `session.run` take them."""
    from .distributed import ShardError
    from .files import RunError, os_error_text

    again = again or f"swarmcode-torch evolve --resume {run_dir}"
    writers = session.file_reporters(
        run_dir,
        checkpoint_every,
        render_every,
        figure_every,
        saved=saved,
        snapshot_every=snapshot_every,
    )
    checkpoints = writers[-1]
    extra: list = []
    if wandb_project is not None:  # after the checkpoints: outside the step
        from .reporting import WandbReporter

        extra.append(WandbReporter(wandb_project, run_dir, render_every))
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
    except RunError as e:
        if progress is not None:
            progress.stop()
        close_writers(reporters)
        fail(f"{e}; {last_checkpoint(checkpoints.saved)}")
    except OSError as e:
        progress.stop()
        close_writers(reporters)
        what = (
            f"writing the run's files failed after {ev.state.generation} generations "
            f"({os_error_text(e)})"
        )
        if checkpoints.saved is None:
            fail(
                f"{what}; no checkpoint was written yet: free space or fix the cause, then start "
                "the run again"
            )
        fail(
            f"{what}; {last_checkpoint(checkpoints.saved)} "
            f"({run_dir / 'checkpoint.pt'}); free space or fix the cause, then continue with: "
            f"{again}"
        )
    except ShardError as e:
        progress.stop()
        close_writers(reporters)
        fail(
            f"{e} after {ev.state.generation} generations; {last_checkpoint(checkpoints.saved)} "
            f"({run_dir / 'checkpoint.pt'}); continue with: {again}"
        )
    progress.stop()


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


def _num(v, fmt: str) -> str:
    return "n/a" if v is None else format(v, fmt)


def best_interval(s: dict) -> str:
    """How summary.json's best fitness was measured, for the line after it: " (mean of K fresh
    environments, 95 % interval LO to HI; the highest single evaluation of the run: F in
    generation G)"; "" for a run whose best team was not re-evaluated."""
    k, ci = s.get("best_reeval_trials"), s.get("best_fitness_ci95")
    if not k:
        return ""
    interval = f", 95 % interval {ci[0]:.2f} to {ci[1]:.2f}" if ci else ""
    single = s.get("best_single_trial_fitness")
    highest = (
        f"; the highest single evaluation of the run: {single:.2f} in generation "
        f"{s.get('best_single_trial_generation')}"
        if single is not None
        else ""
    )
    return f" (mean of {k} fresh environments{interval}{highest})"


def print_team(run_dir: Path) -> None:
    from .runs import RunError, read_summary

    try:
        s = read_summary(run_dir)
    except RunError as e:
        fail(str(e))
    designs = s["designs"]
    budget = "none" if s.get("budget") is None else f"${s['budget']:g}"
    console.print(
        f"Best team (generation {s['best_generation']}): fitness {_num(s['best_fitness'], '.2f')}"
        f"{best_interval(s)}, cost ${_num(s['team_cost'], '.0f')} (budget {budget}), {s['num_species']} species, "
        f"deliveries {_num(s['deliveries'], '.2f')} ({_num(s['deliveries_individual'], '.2f')} "
        f"individual, {_num(s['deliveries_collab'], '.2f')} collaborative), energy used "
        f"{_num(s['energy_used'], '.1f')}%",
        markup=False,
    )
    t = Table(
        title="Robots per design",
        box=box.SIMPLE_HEAD,
        caption="ch/bat/mot: chassis, battery, motor tier (1-3); torque, capacity: "
        "operating points (0-1); dom: dominance",
    )
    for col in (
        "robots",
        "species",
        "tool",
        "radius",
        "ch",
        "bat",
        "mot",
        "torque",
        "capacity",
        "dom",
        "$ each",
    ):
        t.add_column(col, justify="right", no_wrap=True)
    for d in designs:
        t.add_row(
            str(d["count"]),
            str(d["species"]),
            d["effector"],
            f"{d['radius']:.3f}",
            str(d["chassis_tier"]),
            str(d["battery_tier"]),
            str(d["motor_tier"]),
            f"{d['torque_point']:.2f}",
            f"{d['battery_point']:.2f}",
            f"{d['dominance']:.2f}",
            f"{d['cost']:.0f}",
        )
    console.print(t)
    return designs
