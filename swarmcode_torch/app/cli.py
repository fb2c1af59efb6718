"""The `swarmcode-torch` command line: scenarios, evolve, inspect."""

from __future__ import annotations

import json
import math
import signal
import sys
import threading
from contextlib import ExitStack, contextmanager
from dataclasses import replace
from enum import Enum
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich import box
from rich.console import Console
from rich.markup import escape
from typer.core import TyperGroup
from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                           TimeRemainingColumn)
from rich.table import Table

from ..sim import bt
from ..sim.scenario import ScenarioError, builtin_names, load_scenario
from .runs import deferred_signals

class _OneLineErrors(TyperGroup):
    """The command group, with usage errors (an option value that is not a number, an unknown
    option) printed as one line, like every other error, instead of a usage panel."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        try:
            rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except Exception as e:  # noqa: BLE001 - only click's own exceptions are handled here
            if not (hasattr(e, "format_message") and hasattr(e, "exit_code")):
                if type(e).__name__ == "Abort":
                    err.print("Aborted!", markup=False)
                    sys.exit(1)
                raise
            if type(e).__name__ == "NoArgsIsHelpError":
                from typer import rich_utils

                rich_utils.rich_format_error(e)
                sys.exit(e.exit_code)
            ctx = getattr(e, "ctx", None)
            hint = f" (see: {ctx.command_path} --help)" if ctx is not None else ""
            msg = " ".join(e.format_message().split())
            err.print(f"[bold red]Error:[/] {escape(msg + hint)}", highlight=False, soft_wrap=True)
            sys.exit(e.exit_code)
        sys.exit(rv if isinstance(rv, int) else 0)


# shell completion (--install-completion) is on: it is how --device, --objective and the other
# choices reach a shell; each completion runs the CLI's import (torch), so it takes a second or two
app = typer.Typer(add_completion=True, no_args_is_help=True, cls=_OneLineErrors, rich_markup_mode=None,
                  help="SwarmCoDe: co-design the behavior trees and hardware of robot swarms.")
# off a terminal (logs, pipes) Rich would wrap at 80 columns; tables need a little more
console = Console(width=None if sys.stdout.isatty() else 120)
err = Console(stderr=True, width=None if sys.stderr.isatty() else 200)


class Objective(str, Enum):
    """--objective: its choices, in --help and in shell completion."""

    fitness = "fitness"
    roi = "roi"


#: --device: shown in --help as its choices; the value is checked with the run's other settings
#: (`SwarmCoDeConfig.validate`), so that its error reads as theirs.
DEVICE_METAVAR = "[auto|cpu|cuda|cuda:N]"
DEVICES = ("auto", "cpu", "cuda", "cuda:0")


def _complete_device(incomplete: str) -> list[str]:
    """Shell completion of --device."""
    return [d for d in DEVICES if d.startswith(incomplete)]


def _objective(value: "Objective | None") -> str | None:
    return None if value is None else Objective(value).value


class _Failed(typer.Exit):
    """The exit (code 2) of `fail`; `message` is its line (a sweep's Ray task reports it)."""

    def __init__(self, message: str):
        super().__init__(code=2)
        self.message = message


def _print_version(value: bool) -> None:
    if value:
        from .. import __version__
        console.print(f"swarmcode-torch {__version__}", highlight=False)
        raise typer.Exit()


@app.callback()
def _options(version: Annotated[Optional[bool], typer.Option(
        "--version", callback=_print_version, is_eager=True,
        help="Print the version and exit.")] = None) -> None:
    """SwarmCoDe: co-design the behavior trees and hardware of robot swarms."""


def fail(msg: str) -> None:
    """Print a one-line error and exit non-zero. The message is printed as it is: brackets such
    as [low, high] or [[packages]] are not read as Rich markup; a newline inside it becomes a
    space, so the error stays on one line."""
    msg = " ".join(str(msg).split())
    err.print(f"[bold red]Error:[/] {escape(msg)}", highlight=False, soft_wrap=True)
    raise _Failed(msg)


#: The longest path an option takes (PATH_MAX).
MAX_PATH = 4096


def _path(value: str | None, option: str) -> Path | None:
    """An option's path, checked: not empty (an empty --logdir would write into the working
    directory; '.' says so), at most MAX_PATH characters, no NUL, and text that can be printed
    (bytes that are not UTF-8 reach Python as surrogates no message can print)."""
    if value is None:
        return None
    if not value.strip():
        fail(f"{option} is empty: give a directory ('.' for the working directory)")
    if len(value) > MAX_PATH or "\0" in value:
        fail(f"{option}: not a path ({len(value)} characters{', a NUL' if chr(0) in value else ''};"
             f" at most {MAX_PATH})")
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        fail(f"{option}: the path {value.encode('utf-8', 'backslashreplace').decode()[:200]} "
             "is not UTF-8 text; rename it or give another")
    return Path(value)


def _os_fail(e: OSError, doing: str) -> None:
    from .runs import os_error_text

    fail(f"{doing}: {os_error_text(e)}")


@app.command()
def scenarios() -> None:
    """List the built-in scenarios."""
    t = Table(title="Built-in scenarios (use with --scenario NAME, or give a .toml file)",
              box=box.SIMPLE_HEAD)
    rows = []
    for name in builtin_names():
        s = load_scenario(name)
        collab = sum(p.count for p in s.packages if p.kind == "collab")
        rows.append((name, str(s.num_robots), str(s.num_packages - collab), str(collab),
                     str(s.episode_ticks), f"{s.species_overhead:g}", s.description))
    for i, col in enumerate(("name", "robots", "packages", "collab", "ticks", "$/species",
                             "description")):
        fixed = i < 6  # every column but the description keeps its full width
        t.add_column(col, no_wrap=True, overflow="ellipsis",
                     min_width=max(len(col), *(len(r[i]) for r in rows)) if fixed else None)
    for r in rows:
        t.add_row(*r)
    # on a terminal a description is cut to the window; off one (a pipe, a file) every row is
    # one whole line, however long
    (console if console.is_terminal else Console(width=100_000, highlight=False)).print(t)


class _Progress:
    """Rich progress bar on a terminal; a plain line every few generations otherwise."""

    def __init__(self, total: int, start: int, every: int):
        self.tty = sys.stdout.isatty()
        self.every = every
        self.bar = None
        if self.tty:
            self.bar = Progress(TextColumn("done"), MofNCompleteColumn(), BarColumn(),
                                TextColumn("{task.description}"), TimeElapsedColumn(),
                                TextColumn("left"), TimeRemainingColumn(), console=console)
            self.task = self.bar.add_task("", total=total, completed=start)

    def on_start(self, ev) -> None:
        if self.bar:
            self.bar.start()

    def on_generation(self, ev, r) -> None:
        # generations are numbered from 0 (summary.json, teams.jsonl, TensorBoard steps); the
        # count "done" is how many have finished: generation g is the (g + 1)-th
        team = r.team
        text = (f"generation {r.generation}  best team {r.best['fitness']:.1f} "
                f"(this generation {team['fitness']:.1f})  species {r.num_species}  "
                f"team {team['species']} sp, {team['niches']} niches, "
                f"${team['cost']:.0f}  {r.seconds:.2f}s/gen")
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


@app.command()
def evolve(
    scenario: Annotated[Optional[str], typer.Option(help="Built-in scenario name or a scenario .toml file.")] = None,
    budget: Annotated[Optional[float], typer.Option(help="Fabrication budget in $ (default: none, no penalty).")] = None,
    objective: Annotated[Optional[Objective], typer.Option(help="fitness, or roi: fitness / team cost [default: fitness].")] = None,
    generations: Annotated[Optional[int], typer.Option(help="Total generations (with --resume: extend to this many).")] = None,
    population: Annotated[Optional[int], typer.Option(help="Individuals in the population [default: 100].")] = None,
    swarm_size: Annotated[Optional[int], typer.Option(help="Robots per team [default: the scenario's].")] = None,
    trials: Annotated[Optional[int], typer.Option(help="Random environments per team evaluation [default: 3].")] = None,
    ticks: Annotated[Optional[int], typer.Option(help="Episode length in ticks [default: the scenario's].")] = None,
    seed: Annotated[Optional[int], typer.Option(help="Random seed [default: 0].")] = None,
    device: Annotated[Optional[str], typer.Option(metavar=DEVICE_METAVAR, autocompletion=_complete_device, help="Where the run computes: auto (cuda if available), cpu, cuda or cuda:N [default: auto].")] = None,
    compile: Annotated[Optional[bool], typer.Option("--compile/--no-compile", help="torch.compile the tick [default: on CUDA, and on CPU for >= 50 generations].")] = None,
    logdir: Annotated[Optional[str], typer.Option(metavar="PATH", help="Directory that holds run directories [default: runs].")] = None,
    checkpoint_every: Annotated[int, typer.Option(help="Generations between checkpoints.")] = 10,
    log_every: Annotated[int, typer.Option(help="Generations between log lines when not on a terminal.")] = 10,
    render_every: Annotated[int, typer.Option(help="Generations between replay images in TensorBoard (0: never).")] = 50,
    figure_every: Annotated[int, typer.Option(help="Generations between species-composition figures in TensorBoard (one is also drawn at the end of every run).")] = 50,
    resume: Annotated[Optional[str], typer.Option(metavar="PATH", help="Continue the run in this directory.")] = None,
    preset: Annotated[Optional[str], typer.Option(help="Algorithm settings to start from: default, or paper (the paper's text and nothing beyond it); --set goes on top [default: default].")] = None,
    settings: Annotated[Optional[list[str]], typer.Option("--set", metavar="KEY=VALUE", help="Set an algorithm config key, e.g. --set p_tag_flip=0.0625 (repeatable; keys as in the run's config.toml).")] = None,
    eval_workers: Annotated[int, typer.Option(help="Evaluate each generation in this many shards on Ray actors, one GPU each on CUDA, else CPUs (needs Ray; same results as 1).")] = 1,
    cpus_per_eval_worker: Annotated[Optional[float], typer.Option(help="Ray: CPUs (and torch threads) of each evaluation actor on the CPU [default: 1].")] = None,
    ray_address: Annotated[Optional[str], typer.Option(help="Ray: join the cluster at auto or HOST:PORT for the evaluation shards [default: start a local one].")] = None,
    threads: Annotated[Optional[int], typer.Option(help=THREADS_HELP)] = None,
    wandb: Annotated[bool, typer.Option("--wandb", help="Also log to Weights & Biases (the scalars, the config, the replays; needs swarmcode-torch[wandb]; WANDB_MODE=offline for no network).")] = False,
    wandb_project: Annotated[str, typer.Option(help="Weights & Biases project of --wandb.")] = "swarmcode-torch",
) -> None:
    """Evolve a heterogeneous swarm (defaults: the paper's budget experiment)."""
    logdir, resume = _path(logdir, "--logdir"), _path(resume, "--resume")
    wandb_project = _wandb_option(wandb, wandb_project)
    _TERMINATED.clear()                    # this command's SIGTERM, not an earlier one's
    _set_threads(threads)
    shards = _eval_shards_option(eval_workers, cpus_per_eval_worker, ray_address)
    where = _Where()
    with _terminate_as_interrupt() as terminated:
        try:
            with ExitStack() as stack:
                attach = None if shards is None else (lambda ev: _attach_shards(stack, ev, *shards))
                ev, run_dir, saved = _start_evolve(
                    stack, scenario=scenario, budget=budget, objective=_objective(objective),
                    generations=generations, population=population, swarm_size=swarm_size,
                    trials=trials, ticks=ticks, seed=seed, device=device, compile=compile,
                    logdir=logdir, checkpoint_every=checkpoint_every, log_every=log_every,
                    render_every=render_every, resume=resume, settings=settings, attach=attach,
                    figure_every=figure_every, where=where, preset=preset)
                if ev is None:
                    return
                _execute(ev, run_dir, checkpoint_every, log_every, render_every, saved=saved,
                         figure_every=figure_every, where=where, wandb_project=wandb_project)
                if shards is not None:
                    _print_shard_traffic(ev.ctx.evaluator)
            console.print(f"Done: {ev.state.generation} generations in {escape(str(run_dir))}")
            _print_team(run_dir)
            console.print(f"Inspect: swarmcode-torch inspect {run_dir}   Watch: tensorboard "
                          f"--logdir {run_dir.parent}", markup=False, highlight=False)
        except KeyboardInterrupt:
            _stopped(where, bool(terminated))


class _Where:
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


def _stop_line(how: str, run_dir: Path | None, saved: int | None, again: str | None,
               resuming: bool = False) -> str:
    """The line an interrupted run prints: the generation its checkpoint file really holds, or
    that there is none."""
    if run_dir is None:
        return f"{how}: no run directory was made"
    if saved is None:
        if resuming:
            return f"{how} before the run resumed; {run_dir} is unchanged"
        return (f"{how}: no checkpoint was written yet, so {run_dir} holds no generation to "
                "continue from; start the run again")
    done = "no generation finished yet" if saved == 0 else \
        f"generations 0-{saved - 1} recorded"
    again = again or f"swarmcode-torch evolve --resume {run_dir}"
    return (f"{how}: checkpoint of generation {saved} is in {run_dir} ({done}); continue "
            f"with: {again}")


def _stopped(where: _Where, terminated: bool) -> None:
    terminated = terminated or bool(_TERMINATED)
    how = "Terminated" if terminated else "Interrupted"
    err.print(_stop_line(how, where.run_dir, where.holds(), where.again, where.resuming),
              markup=False, highlight=False, soft_wrap=True)
    raise typer.Exit(code=143 if terminated else 130)


THREADS_HELP = ("CPU threads of this process [default: OMP_NUM_THREADS if set, else the cores "
                "less the load average, at least 1].")


def _set_threads(threads: int | None) -> None:
    from ..sim.runtime import set_threads

    try:
        set_threads(threads)
    except ValueError:
        fail(f"--threads must be >= 1, got {threads}")


def _eval_shards_option(eval_workers: int, cpus: float | None, address: str | None):
    """(workers, CPUs per worker, address) of a sharded evaluation, or None for the evaluation
    in this process; a one-line error for bad values or Ray options without Ray."""
    if eval_workers < 1:
        fail(f"--eval-workers must be >= 1, got {eval_workers}")
    if eval_workers == 1 and address is None:
        if cpus is not None:
            fail("--cpus-per-eval-worker is for evaluation shards on Ray: use it with "
                 "--eval-workers N > 1 or --ray-address")
        return None
    if cpus is not None and not (cpus > 0 and math.isfinite(cpus)):
        fail(f"--cpus-per-eval-worker must be a finite number > 0, got {cpus}")
    _need_ray(f"--eval-workers {eval_workers}" if eval_workers > 1 else "--ray-address")
    return eval_workers, 1.0 if cpus is None else cpus, address


def _need_ray(what: str) -> None:
    """A one-line error naming the extra to install when Ray is missing."""
    from .distributed import RayUnavailable, require_ray

    try:
        require_ray(what)
    except RayUnavailable as e:
        fail(str(e))


def _attach_shards(stack: ExitStack, ev, workers: int, cpus: float, address: str | None) -> None:
    """Evaluate `ev`'s generations in shards on Ray actors until `stack` closes."""
    from .distributed import RayUnavailable, sharded_evaluation

    try:
        evaluator = stack.enter_context(sharded_evaluation(ev, workers, address, cpus))
    except RayUnavailable as e:
        fail(str(e))
    where = sorted(set(evaluator.where))
    console.print(f"Evaluation: {workers} shards on Ray actors ({escape('; '.join(where))})",
                  highlight=False)


def _print_shard_traffic(evaluator) -> None:
    stats = getattr(evaluator, "stats", None)
    if not stats:
        return
    n = len(stats)
    sent = sum(s["bytes_sent"] for s in stats) / n
    back = sum(s["bytes_received"] for s in stats) / n
    console.print(f"Evaluation shards: {sent / 1024:.1f} KiB sent and {back / 1024:.1f} KiB "
                  f"received per generation (pickled, mean of {n} generations)",
                  highlight=False, markup=False)


def _start_evolve(stack: ExitStack, *, scenario, budget, objective, generations, population,
                  swarm_size, trials, ticks, seed, device, compile, logdir, checkpoint_every,
                  log_every, render_every, resume, settings, attach=None, figure_every=50,
                  where: "_Where | None" = None, preset=None):
    """Check the options, then make (or lock and reopen) the run directory: (Evolution, run
    directory, generation of its checkpoint), or (None, ...) when a resume has nothing to do.
    The run directory's lock is held until `stack` closes. `attach(ev)`, if given, is called
    once the Evolution exists and before any file is written (evaluation shards)."""
    from ..coevo.config import preset_config, with_overrides
    from ..coevo.evolve import Evolution
    from .settings import option_names, parse_settings
    from .runs import (RunError, RunLock, check_config, load_run, new_run_dir, write_config,
                       write_run_files)
    from .runs import resume as resume_run
    from ..sim.scenario import read_scenario

    if checkpoint_every < 1 or log_every < 1 or figure_every < 1 or render_every < 0:
        fail("--checkpoint-every, --log-every and --figure-every must be >= 1, "
             "--render-every >= 0")
    given = dict(scenario=scenario, budget=budget, objective=objective, population=population,
                 swarm_size=swarm_size, trials=trials, ticks=ticks, seed=seed, compile=compile)
    try:
        if resume is not None:
            if generations is not None and generations < 1:
                fail(f"--generations must be >= 1 (the total to extend the run to), got "
                     f"{generations}")
            extra = [k.replace("_", "-") for k, v in given.items() if v is not None]
            extra += ["set"] if settings else []
            extra += ["preset"] if preset is not None else []
            if extra:
                fail(f"--resume uses the run's saved config; only --generations and --device may "
                     f"change (got --{', --'.join(extra)})")
            if logdir is not None:
                fail(f"--logdir cannot be used with --resume: the run continues in its own "
                     f"directory ({resume})")
            if not resume.is_dir():
                fail(f"--resume {resume} is not a run directory (no such directory)")
            run_dir = resume
            stack.enter_context(RunLock(run_dir))
            if where is not None:
                where.run_dir, where.resuming = run_dir, True
            loaded = load_run(run_dir)
            cfg, ck = loaded[0], loaded[1]
            if where is not None:
                where.saved = ck["generation"]
            target = cfg.generations if generations is None else generations
            if target <= ck["generation"]:
                console.print(f"{run_dir} already has {ck['generation']} generations"
                              f"{'' if generations is None else f' (asked for {generations})'}; "
                              "nothing to do, no file changed", markup=False, highlight=False,
                              soft_wrap=True)
                return None, run_dir, None
            ev = resume_run(run_dir, generations=generations, device=device, loaded=loaded)
            if attach is not None:
                attach(ev)
            write_config(run_dir, ev.cfg)
            console.print(f"Resuming [bold]{escape(str(run_dir))}[/] at generation "
                          f"{ev.state.generation} of {ev.cfg.generations}")
            return ev, run_dir, ev.state.generation
        # --set values are applied as given, none included (with_overrides skips None)
        cfg = replace(with_overrides(preset_config(preset or "default"), generations=generations,
                                     device=device, **given), **parse_settings(settings or []))
        cfg.validate(option_names(), bounds=False)
        scen, data = read_scenario(cfg.scenario)  # a clear error before anything is created
        check_config(cfg, scen, option_names())
        logdir = logdir if logdir is not None else Path("runs")
        if logdir.exists() and not logdir.is_dir():
            fail(f"--logdir {logdir} is not a directory")
        ev = Evolution(cfg)
        if ev.ctx.scenario != scen:
            fail(f"{cfg.scenario} changed while the run was starting; start it again")
        if attach is not None:
            attach(ev)
        try:
            run_dir = new_run_dir(logdir, cfg)
        except OSError as e:
            _os_fail(e, f"--logdir {logdir}: cannot make a run directory")
        stack.enter_context(RunLock(run_dir))
        if where is not None:
            where.run_dir = run_dir
        write_run_files(run_dir, ev.cfg, data, ev.ctx.scenario.hardware)
        console.print(f"Run directory: [bold]{escape(str(run_dir))}[/]  (device {ev.ctx.device}, "
                      f"scenario {escape(ev.ctx.scenario.name)}, population {cfg.population}, "
                      f"swarm {ev.ctx.eval_cfg.swarm_size}, tick {ev.ctx.tick_mode})")
        return ev, run_dir, None
    except (ScenarioError, RunError, ValueError) as e:
        fail(str(e))
    except OSError as e:
        _os_fail(e, "cannot start the run")


def _execute(ev, run_dir: Path, checkpoint_every: int, log_every: int,
             render_every: int = 0, saved: int | None = None,
             again: str | None = None, figure_every: int = 50,
             where: _Where | None = None, wandb_project: str | None = None) -> None:
    """Run `ev` to its last generation with progress, summary, TensorBoard and checkpoints
    (and Weights & Biases with `wandb_project`).
    Ctrl-C and SIGTERM write the checkpoint of the last finished generation (exit 130, 143). A
    failed write (a full disk: OSError from the checkpoint, summary.json, teams.jsonl or
    TensorBoard) ends the run with a one-line error that names the last checkpointed generation
    and how to continue (exit 2); the checkpoint on disk is the last complete one. `saved` is the
    generation of the checkpoint the run resumed from; `again` is the command to continue with
    (default: swarmcode-torch evolve --resume RUN_DIR)."""
    from .distributed import ShardError
    from .runs import CheckpointReporter, RunError, SummaryReporter, os_error_text, run

    again = again or f"swarmcode-torch evolve --resume {run_dir}"
    checkpoints = CheckpointReporter(run_dir, checkpoint_every)
    checkpoints.saved = saved
    if where is not None:
        where.run_dir, where.checkpoints, where.again = run_dir, checkpoints, again
    reporters: list = []
    terminated: list[int] = []
    progress = None
    try:
        progress = _Progress(ev.cfg.generations, ev.state.generation, log_every)
        reporters = [progress, SummaryReporter(run_dir)]
        with _quiet_thread_os_errors():
            from .reporting import CsvReporter, TensorBoardReporter

            reporters += [CsvReporter(run_dir),
                          TensorBoardReporter(run_dir, figure_every=figure_every,
                                              render_every=render_every), checkpoints]
            if wandb_project is not None:      # after the checkpoints: outside the step
                from .reporting import WandbReporter

                reporters.append(WandbReporter(wandb_project, run_dir, render_every))
            with _terminate_as_interrupt() as terminated:
                run(ev, run_dir, reporters)
    except KeyboardInterrupt:
        with deferred_signals(deliver=False):      # the writers close whole (TensorBoard's thread)
            if progress is not None:
                progress.stop()
            _close_writers(reporters)
        stopped = bool(terminated or _TERMINATED)      # SIGTERM here or before the run loop
        err.print(_stop_line("Terminated" if stopped else "Interrupted", run_dir,
                             checkpoints.saved, again), markup=False, highlight=False,
                  soft_wrap=True)
        raise typer.Exit(code=143 if stopped else 130)
    except RunError as e:
        if progress is not None:
            progress.stop()
        _close_writers(reporters)
        fail(f"{e}; the last checkpoint is of generation {checkpoints.saved}")
    except OSError as e:
        progress.stop()
        _close_writers(reporters)
        what = (f"writing the run's files failed after {ev.state.generation} generations "
                f"({os_error_text(e)})")
        if checkpoints.saved is None:
            fail(f"{what}; no checkpoint was written yet: free space or fix the cause, then start "
                 "the run again")
        fail(f"{what}; the last checkpoint is of generation {checkpoints.saved} "
             f"({run_dir / 'checkpoint.pt'}); free space or fix the cause, then continue with: "
             f"{again}")
    except ShardError as e:
        progress.stop()
        _close_writers(reporters)
        fail(f"{e} after {ev.state.generation} generations; the last checkpoint is of "
             f"generation {checkpoints.saved} ({run_dir / 'checkpoint.pt'}); continue with: "
             f"{again}")
    progress.stop()


def _wandb_option(on: bool, project: str) -> str | None:
    """The W&B project of `evolve --wandb` (None: off); a one-line error without wandb."""
    if not on:
        return None
    from .reporting import require_wandb

    try:
        require_wandb()
    except ImportError as e:
        fail(str(e))
    return project


def _close_writers(reporters) -> None:
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
def _quiet_thread_os_errors():
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


#: Set once SIGTERM has arrived in this process (the exit status is then 143, not 130).
_TERMINATED: list[int] = []


@contextmanager
def _terminate_as_interrupt():
    """Within the block SIGTERM (a scheduler's or `kill`'s stop) acts as Ctrl-C: the run writes
    the checkpoint of its last finished generation. A second SIGTERM while that checkpoint is
    written is ignored, so the write completes. Yields a list that is non-empty once SIGTERM
    has arrived."""
    terminated: list[int] = []

    def handler(signum, frame):
        if terminated:
            return                         # already stopping: let the checkpoint be written
        terminated.append(signum)
        _TERMINATED.append(signum)
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:                     # not the main thread: leave signals alone
        yield terminated
        return
    try:
        yield terminated
    finally:
        signal.signal(signal.SIGTERM, previous)


def _parse_list(text: str, kind, option: str) -> list:
    try:
        vals = [kind(x) for x in text.split(",") if x.strip()]
    except ValueError:
        fail(f"{option} expects a comma-separated list of numbers, got {text!r}")
    if not vals:
        fail(f"{option} is empty")
    for v in vals:
        if kind is float and not math.isfinite(v):
            fail(f"{option}: {v} is not a finite number")
        if vals.count(v) > 1:
            fail(f"{option} lists {v:g} twice (each run is one budget and one seed)")
    return vals


@app.command()
def sweep(
    budgets: Annotated[str, typer.Option(help="Comma-separated budgets in $.")] = "2500,3000,4000,5000,6000,8000",
    seeds: Annotated[str, typer.Option(help="Comma-separated seeds; one run per budget and seed.")] = "0",
    objective: Annotated[Optional[Objective], typer.Option(help="fitness, or roi: fitness / team cost [default: fitness].")] = None,
    scenario: Annotated[Optional[str], typer.Option(help="Scenario [default: budget].")] = None,
    generations: Annotated[Optional[int], typer.Option(help="Generations per run [default: 500].")] = None,
    population: Annotated[Optional[int], typer.Option(help="Population [default: 100].")] = None,
    swarm_size: Annotated[Optional[int], typer.Option(help="Robots per team [default: the scenario's].")] = None,
    trials: Annotated[Optional[int], typer.Option(help="Environments per evaluation [default: 3].")] = None,
    ticks: Annotated[Optional[int], typer.Option(help="Episode length [default: the scenario's].")] = None,
    device: Annotated[Optional[str], typer.Option(metavar=DEVICE_METAVAR, autocompletion=_complete_device, help="auto (cuda if available), cpu, cuda or cuda:N [default: auto].")] = None,
    compile: Annotated[Optional[bool], typer.Option("--compile/--no-compile", help="torch.compile the tick.")] = None,
    logdir: Annotated[Optional[str], typer.Option(metavar="PATH", help="Directory that holds the new sweep directory, sweep-<time>, as evolve's --logdir holds run directories [default: runs].")] = None,
    out: Annotated[Optional[str], typer.Option(metavar="PATH", help="The sweep directory itself [default: LOGDIR/sweep-<time>]; run again with the same --out to resume.")] = None,
    checkpoint_every: Annotated[int, typer.Option(help="Generations between checkpoints.")] = 10,
    log_every: Annotated[int, typer.Option(help="Generations between log lines off a terminal.")] = 50,
    preset: Annotated[Optional[str], typer.Option(help="Algorithm settings to start from, as in evolve [default: default].")] = None,
    settings: Annotated[Optional[list[str]], typer.Option("--set", metavar="KEY=VALUE", help="Set an algorithm config key of every run (repeatable), as in evolve.")] = None,
    workers: Annotated[int, typer.Option(help="Runs at once; > 1 runs them as Ray tasks (needs Ray).")] = 1,
    cpus_per_run: Annotated[Optional[float], typer.Option(help="Ray: CPUs (and torch threads) each run reserves [default: 1].")] = None,
    gpus_per_run: Annotated[Optional[float], typer.Option(help="Ray: GPUs each run reserves; 0.25 packs four runs on a GPU [default: 0].")] = None,
    ray_address: Annotated[Optional[str], typer.Option(help="Ray: join the cluster at auto or HOST:PORT [default: start a local one]; the runs go to Ray.")] = None,
    threads: Annotated[Optional[int], typer.Option(help=THREADS_HELP)] = None,
) -> None:
    """One evolution per budget (and seed); writes the paper's Table III as Markdown and CSV, and a plot."""
    _set_threads(threads)
    import time

    from ..coevo.config import preset_config, with_overrides
    from .settings import option_names, parse_settings
    from .runs import SWEEP_LOCK_FILE, TABLE_MD, RunError, RunLock, check_config, read_summary
    from ..sim.scenario import read_scenario
    from .sweep import table_rows, write_outputs

    logdir, out = _path(logdir, "--logdir"), _path(out, "--out")
    _TERMINATED.clear()
    budget_list = _parse_list(budgets, float, "--budgets")
    seed_list = _parse_list(seeds, int, "--seeds")
    if checkpoint_every < 1 or log_every < 1:
        fail("--checkpoint-every and --log-every must be >= 1")
    on_ray = _sweep_ray_options(workers, cpus_per_run, gpus_per_run, ray_address, device)
    if logdir is not None and out is not None:
        fail(f"--logdir and --out cannot both be given: --out is the sweep directory itself "
             f"({out}), --logdir the directory a new one is made in ({logdir})")
    if logdir is not None and logdir.exists() and not logdir.is_dir():
        fail(f"--logdir {logdir} is not a directory")
    out = out or (logdir or Path("runs")) / f"sweep-{time.strftime('%Y%m%d-%H%M%S')}"
    names = option_names({"seed": "--seeds", "budget": "--budgets"})
    try:
        base = replace(with_overrides(preset_config(preset or "default"),
                                      objective=_objective(objective),
                                      scenario=scenario, generations=generations,
                                      population=population, swarm_size=swarm_size,
                                      trials=trials, ticks=ticks, device=device,
                                      compile=compile), **parse_settings(settings or [], names))
        for b in budget_list:
            for sd in seed_list:
                with_overrides(base, budget=b, seed=sd).validate(option_names=names, bounds=False)
        scen, data = read_scenario(base.scenario)
        for b in budget_list:
            for sd in seed_list:
                check_config(with_overrides(base, budget=b, seed=sd), scen, names)
    except (ScenarioError, ValueError) as e:
        fail(str(e))
    if out.exists() and not out.is_dir():
        fail(f"--out {out} is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        _os_fail(e, f"--out {out}: cannot make the sweep directory")
    runs = []
    with ExitStack() as stack:
        try:
            stack.enter_context(RunLock(out, SWEEP_LOCK_FILE))
        except RunError as e:
            fail(str(e))
        except OSError as e:
            _os_fail(e, f"--out {out}: cannot lock the sweep directory")
        plans = [_plan_sweep_run(out, with_overrides(base, budget=b, seed=sd), scen, data)
                 for b in budget_list for sd in seed_list]      # every refusal before any run
        again = f"swarmcode-torch sweep with the same options and --out {out}"
        console.print(f"Sweep directory: {out} (resume with --out {out})", markup=False,
                      highlight=False, soft_wrap=True)
        failed: list[tuple[str, str]] = []
        if on_ray is None:
            for b, sd, run_dir, cfg, state in plans:
                if state != "done":
                    _run_sweep_run(run_dir, cfg, data, state, checkpoint_every, log_every, again)
                runs.append((b, sd, run_dir))
        else:
            runs, failed = _sweep_on_ray(plans, data, checkpoint_every, log_every, again, *on_ray)
            if not runs:
                fail(f"every run of the sweep failed ({failed[0][0]}: {failed[0][1]}); fix the "
                     f"cause, then run it again: {again}")
        try:
            for _, _, run_dir in runs:
                read_summary(run_dir)                  # every figure of the table is checked
            rows = table_rows(runs)
            paths = write_outputs(rows, out)
        except (RunError, ValueError) as e:
            fail(str(e))
        except OSError as e:
            _os_fail(e, f"--out {out}: cannot write the table")
    console.print((out / TABLE_MD).read_text(), highlight=False, markup=False)
    console.print("Wrote " + ", ".join(str(p) for p in paths), highlight=False, markup=False)
    if failed:
        names = ", ".join(name for name, _ in failed)
        fail(f"{len(failed)} of {len(plans)} runs failed ({names}); the table has the "
             f"{len(runs)} that finished; fix the cause, then resume them: {again}")


def _sweep_ray_options(workers: int, cpus: float | None, gpus: float | None,
                       address: str | None, device: str | None):
    """(workers, CPUs per run, GPUs per run, address) of a sweep on Ray, or None for the runs
    one after the other in this process; a one-line error for bad values or Ray options without
    Ray."""
    if workers < 1:
        fail(f"--workers must be >= 1, got {workers}")
    if workers == 1 and address is None:
        if cpus is not None or gpus is not None:
            fail("--cpus-per-run and --gpus-per-run are for runs on Ray: use them with "
                 "--workers N > 1 or --ray-address")
        return None
    for name, v in (("--cpus-per-run", cpus), ("--gpus-per-run", gpus)):
        if v is not None and not (v >= 0 and math.isfinite(v)):
            fail(f"{name} must be a finite number >= 0, got {v}")
    cpus = 1.0 if cpus is None else cpus
    gpus = 0.0 if gpus is None else gpus
    if gpus > 1 and gpus != int(gpus):
        fail(f"--gpus-per-run above 1 must be a whole number of GPUs, got {gpus:g}")
    if device is not None and device.startswith("cuda") and gpus == 0:
        fail(f"--device {device} on Ray needs --gpus-per-run > 0 (each run reserves its share "
             "of a GPU; Ray hides the GPUs from a run that reserves none)")
    _need_ray(f"--workers {workers}" if workers > 1 else "--ray-address")
    return workers, cpus, gpus, address


def _sweep_on_ray(plans, data: bytes, checkpoint_every: int, log_every: int, again: str,
                  workers: int, cpus: float, gpus: float, address: str | None):
    """Run the unfinished runs of a sweep as Ray tasks (`_sweep_task`, up to `workers` at once),
    a line as each ends; ([(budget, seed, run directory)] of the finished runs, in the sweep's
    order, [(run name, error)] of the failed ones)."""
    from .distributed import RayUnavailable, check_resources, ray_session, run_tasks

    todo = [p for p in plans if p[4] != "done"]
    # absolute paths: a worker's working directory may not be this one
    jobs = [(run_dir.resolve(), cfg, data, state, checkpoint_every, log_every, again)
            for _, _, run_dir, cfg, state in todo]
    what = f"--workers {workers}" if workers > 1 else "--ray-address"

    def on_finish(i: int, error: str | None, n: dict) -> None:
        name = todo[i][2].name
        counts = (f"{n['done']} done, {n['running']} running, {n['failed']} failed of "
                  f"{n['total']}")
        if error is None:
            console.print(f"{name}: finished ({counts})", markup=False, highlight=False)
        else:
            console.print(f"{name}: failed: {error} ({counts})", markup=False, highlight=False,
                          soft_wrap=True)

    errors: list = []
    terminated: list = []
    if jobs:
        try:
            with ray_session(address, what) as ray, _terminate_as_interrupt() as terminated:
                check_resources(ray, {"CPU": cpus, "GPU": gpus}, f"a run with --cpus-per-run "
                                f"{cpus:g} and --gpus-per-run {gpus:g}")
                console.print(f"Ray: {len(jobs)} runs, up to {workers} at once ({cpus:g} CPU, "
                              f"{gpus:g} GPU each)", markup=False, highlight=False)
                errors = run_tasks(_sweep_task, jobs, workers=workers, num_cpus=cpus,
                                   num_gpus=gpus, on_finish=on_finish)
        except RayUnavailable as e:
            fail(str(e))
        except KeyboardInterrupt:
            how = "Terminated" if terminated else "Interrupted"
            err.print(f"{how}: the running runs were stopped after writing their checkpoints; "
                      f"continue with: {again}", markup=False, highlight=False)
            raise typer.Exit(code=143 if terminated else 130)
    failed_at = {id(p): e for p, e in zip(todo, errors) if e is not None}
    finished = [p[:3] for p in plans if id(p) not in failed_at]
    failed = [(p[2].name, failed_at[id(p)]) for p in plans if id(p) in failed_at]
    return finished, failed


def _sweep_task(run_dir: Path, cfg, data: bytes, state: str, checkpoint_every: int,
                log_every: int, again: str) -> str | None:
    """One run of a sweep as a Ray task (`distributed.run_tasks`): `_run_sweep_run`, as the
    sweep runs it in this process. None when the run finished; else its error in one line (a
    failed start or write; a stop by Ctrl-C or SIGTERM, after its checkpoint was written)."""
    try:
        _run_sweep_run(run_dir, cfg, data, state, checkpoint_every, log_every, again)
    except _Failed as e:
        return e.message
    except typer.Exit as e:
        return f"stopped (exit {e.exit_code}) after writing its checkpoint"
    except Exception as e:  # noqa: BLE001 - the run's error; the sweep's other runs go on
        return " ".join(f"{type(e).__name__}: {e}".split())
    return None


def _plan_sweep_run(out: Path, cfg, scenario, data: bytes):
    """(budget, seed, run directory, config, state) of one run of a sweep (`sweep.plan_run`),
    state 'done', 'resume' or 'new'; a one-line error for a run it cannot take over."""
    from .runs import RunError
    from .sweep import plan_run, run_name

    try:
        p = plan_run(out, cfg, scenario)
    except (ScenarioError, RunError, ValueError) as e:
        fail(str(e))
    except OSError as e:
        _os_fail(e, f"{out / run_name(cfg.budget, cfg.seed)}: cannot read the run")
    if p.state == "done":
        more = f" (it has {p.done}, more than the {cfg.generations} asked for)" \
            if p.done > cfg.generations else ""
        console.print(f"{p.run_dir.name}: already done{more}", markup=False, highlight=False)
    return p.budget, p.seed, p.run_dir, p.cfg, p.state


def _run_sweep_run(run_dir: Path, cfg, data: bytes, state: str, checkpoint_every: int,
                   log_every: int, again: str) -> None:
    from ..coevo.evolve import Evolution
    from .runs import RunError, RunLock, write_config, write_run_files
    from .runs import resume as resume_run

    with ExitStack() as stack:
        try:
            if state == "resume":
                stack.enter_context(RunLock(run_dir))
                ev = resume_run(run_dir, generations=cfg.generations)
                write_config(run_dir, ev.cfg)
                saved = ev.state.generation
            else:
                ev = Evolution(cfg)            # a config error leaves no directory behind
                run_dir.mkdir(exist_ok=True)
                stack.enter_context(RunLock(run_dir))
                write_run_files(run_dir, ev.cfg, data, ev.ctx.scenario.hardware)
                saved = None
        except (ScenarioError, RunError, ValueError) as e:
            fail(str(e))
        except OSError as e:
            _os_fail(e, f"{run_dir}: cannot start the run")
        console.print(f"[bold]{escape(run_dir.name)}[/]: generation {ev.state.generation} -> "
                      f"{cfg.generations}")
        _execute(ev, run_dir, checkpoint_every, log_every, saved=saved, again=again)


def _num(v, fmt: str) -> str:
    return "n/a" if v is None else format(v, fmt)


def _print_team(run_dir: Path) -> None:
    from .runs import RunError, read_summary

    try:
        s = read_summary(run_dir)
    except RunError as e:
        fail(str(e))
    designs = s["designs"]
    budget = "none" if s.get("budget") is None else f"${s['budget']:g}"
    console.print(
        f"Best team (generation {s['best_generation']}): fitness {_num(s['best_fitness'], '.2f')}, "
        f"cost ${_num(s['team_cost'], '.0f')} (budget {budget}), {s['num_species']} species, "
        f"deliveries {_num(s['deliveries'], '.2f')} ({_num(s['deliveries_individual'], '.2f')} "
        f"individual, {_num(s['deliveries_collab'], '.2f')} collaborative), energy used "
        f"{_num(s['energy_used'], '.1f')}%", markup=False)
    t = Table(title="Robots per design", box=box.SIMPLE_HEAD,
              caption="ch/bat/mot: chassis, battery, motor tier (1-3); torque, capacity: "
                      "operating points (0-1); dom: dominance")
    for col in ("robots", "species", "tool", "radius", "ch", "bat", "mot",
                "torque", "capacity", "dom", "$ each"):
        t.add_column(col, justify="right", no_wrap=True)
    for d in designs:
        t.add_row(str(d["count"]), str(d["species"]), d["effector"], f"{d['radius']:.3f}",
                  str(d["chassis_tier"]), str(d["battery_tier"]), str(d["motor_tier"]),
                  f"{d['torque_point']:.2f}", f"{d['battery_point']:.2f}",
                  f"{d['dominance']:.2f}", f"{d['cost']:.0f}")
    console.print(t)
    return designs


@app.command()
def inspect(run_dir: Annotated[str, typer.Argument(metavar="RUN_DIR", help="A run directory.")]) -> None:
    """Show the best team of a run: robots per design, hardware, cost and behavior trees."""
    run_dir = _path(run_dir, "RUN_DIR")
    if not run_dir.is_dir():
        fail(f"{run_dir} is not a directory")
    designs = _print_team(run_dir)
    caps = _capabilities(run_dir, designs)
    for i, d in enumerate(designs):
        console.print(f"[bold]species {d['species']}[/] ({d['count']} robots, {d['effector']}):")
        if caps is not None:
            labels, can = caps
            lifts = "; ".join(labels[j] for j in can[i]) or "no package class"
            console.print(f"  lifts: {lifts}", highlight=False, markup=False)
        console.print(bt.format_tree(d["bt"], root=True), highlight=False)
    if caps is not None:
        from ..coevo.dynamics import niche_count
        console.print(f"{niche_count(caps[1])} niches (distinct capabilities) in "
                      f"{len({d['species'] for d in designs})} species", highlight=False)


def _capabilities(run_dir: Path, designs: list[dict]):
    """(package class labels, per design the classes it lifts), or None without a scenario."""
    from .analysis import design_capabilities
    from .runs import RunError, read_config, run_scenario

    try:
        scenario = run_scenario(run_dir, read_config(run_dir))
        return [c.label for c in scenario.packages], design_capabilities(designs, scenario)
    except (RunError, ValueError):
        return None


@app.command()
def dynamics(
    run_dir: Annotated[str, typer.Argument(metavar="RUN_DIR", help="A run directory.")],
    window: Annotated[Optional[list[str]], typer.Option(help="Generations A:B (from A to before B); repeatable [default: every 100, and the last 50].")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")] = False,
) -> None:
    """Species dynamics of a run: species in the best team and the population, niches, founding
    and extinction per generation, ages and lifetimes, over windows of generations."""
    from .analysis import run_dynamics
    from .runs import RunError

    run_dir = _path(run_dir, "RUN_DIR")

    if not run_dir.is_dir():
        fail(f"{run_dir} is not a directory")
    wins = []
    for w in window or []:
        a, sep, b = w.partition(":")
        try:
            wins.append((int(a), int(b)))
        except ValueError:
            fail(f"--window expects A:B with integers A < B, got {w!r}")
        if not sep or wins[-1][0] >= wins[-1][1] or wins[-1][0] < 0:
            fail(f"--window expects A:B with integers 0 <= A < B, got {w!r}")
    try:
        stats = run_dynamics(run_dir, wins or None)
    except (RunError, ValueError) as e:
        fail(str(e))
    if as_json:
        console.print_json(json.dumps(stats).replace("NaN", "null"))
        return
    t = Table(title=f"Species dynamics of {run_dir} (medians over each window)",
              box=box.SIMPLE_HEAD, caption="founded, extinct: species a generation (lasting: "
              "founded and alive in 2 generations or more); age, "
              "lifetime: generations; lifetime of the species that died in the window")
    cols = (("from", "from", "{}"), ("to", "to", "{}"), ("team sp", "team_species", "{:g}"),
            ("pop sp", "population_species", "{:g}"), ("niches", "niches", "{:g}"),
            ("founded", "founded_per_generation", "{:.2f}"),
            ("lasting", "founded_lasting_per_generation", "{:.2f}"),
            ("extinct", "extinct_per_generation", "{:.2f}"), ("age", "median_age", "{:g}"),
            ("team age", "team_median_age", "{:g}"), ("lifetime", "median_lifetime", "{:g}"),
            ("team score", "team_score", "{:.1f}"))
    for name, _, _ in cols:
        t.add_column(name, justify="right", no_wrap=True)
    for st in stats:
        t.add_row(*(fmt.format(st[key]) for _, key, fmt in cols))
    console.print(t)


@app.command()
def replay(
    run_dir: Annotated[str, typer.Argument(metavar="RUN_DIR", help="A run directory.")],
    out: Annotated[Optional[str], typer.Option(metavar="PATH", help="Output file [default: RUN_DIR/team.gif, with --html RUN_DIR/team.html].")] = None,
    generation: Annotated[Optional[int], typer.Option(help="Replay this generation's best team instead of the run's.")] = None,
    seed: Annotated[int, typer.Option(help="Seed of the random environment.")] = 0,
    ticks: Annotated[Optional[int], typer.Option(help="Episode length [default: the run's].")] = None,
    every: Annotated[int, typer.Option(help="Draw every k-th tick (GIF).")] = 2,
    html: Annotated[bool, typer.Option("--html", help="Write an interactive page instead: one self-contained HTML file with the team and its baseline team side by side, every tick, each robot's design and behavior tree.")] = False,
) -> None:
    """Render a rollout of the best team headless, as an animated GIF (or, --html, an
    interactive page)."""
    from .analysis import replay_run
    from .runs import RunError

    run_dir, out = _path(run_dir, "RUN_DIR"), _path(out, "--out")

    from ..coevo.config import MAX_SEED, UPPER_BOUNDS

    if every < 1 or (ticks is not None and ticks < 1):
        fail("--every and --ticks must be >= 1")
    if ticks is not None and ticks > UPPER_BOUNDS["ticks"]:
        fail(f"--ticks must be <= {UPPER_BOUNDS['ticks']}, got {ticks}")
    if not 0 <= seed <= MAX_SEED:
        fail(f"--seed must be in [0, {MAX_SEED}] (2**63 - 1), got {seed}")
    if generation is not None and generation < 0:
        fail(f"--generation must be >= 0, got {generation}")
    if not run_dir.is_dir():
        fail(f"{run_dir} is not a directory")
    try:
        path, m = replay_run(run_dir, out=out, seed=seed, ticks=ticks, every=every,
                             generation=generation, html=html)
    except (ScenarioError, RunError, ValueError) as e:
        fail(str(e))
    except OSError as e:
        _os_fail(e, "replay failed")
    console.print(f"Wrote {path}: {'the focal team: ' if html else ''}"
                  f"{m['delivered_individual']:.0f} individual and "
                  f"{m['delivered_collab']:.0f} collaborative deliveries, "
                  f"{m['energy_used']:.1f}% energy used", markup=False, highlight=False)


def main() -> None:
    try:
        app()
    except KeyboardInterrupt:
        # an interrupt outside a run's own handling (while starting, or while a stopped run is
        # closing): no traceback, and the exit status of a stop, never death by SIGINT
        err.print("Interrupted", markup=False, highlight=False)
        sys.exit(143 if _TERMINATED else 130)


if __name__ == "__main__":
    main()
