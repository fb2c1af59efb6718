"""The `swarmcode-torch` command line: its commands and options, parsed, and what they print.

The work is done elsewhere: a run starts and runs through `session` (with `terminal.execute`),
a sweep through `sweep_run`, the analyses in `analysis`."""

from __future__ import annotations

import json
import sys
from contextlib import ExitStack
from dataclasses import replace
from enum import Enum
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich import box
from rich.console import Console
from rich.markup import escape
from typer.core import TyperGroup
from rich.table import Table

from ..coevo.config import SwarmCoDeConfig, with_overrides
from ..sim import bt
from ..sim.scenario import ScenarioError, builtin_names, load_scenario
from . import session
from .settings import parse_settings
from .signals import TERMINATED, terminate_as_interrupt
from .terminal import (THREADS_HELP, Where, attach_shards, check_path, console, err,
                       eval_shards_option, execute, fail, os_fail, print_shard_traffic, print_team,
                       set_threads_option, stopped)


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
                # no command given: the help that --help prints, on stderr with exit 2, as
                # click does for a group called without arguments (a usage error)
                e.show()
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


#: The defaults --help shows for the options that leave them to the run's config.
_DEFAULT = SwarmCoDeConfig()


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


@app.command()
def evolve(
    scenario: Annotated[Optional[str], typer.Option(help=f"Built-in scenario name or a scenario .toml file [default: {_DEFAULT.scenario}].")] = None,
    budget: Annotated[Optional[float], typer.Option(help="Fabrication budget in $ (default: none, no penalty).")] = None,
    objective: Annotated[Optional[Objective], typer.Option(help="fitness, or roi: fitness / team cost [default: fitness].")] = None,
    generations: Annotated[Optional[int], typer.Option(help=f"Total generations [default: {_DEFAULT.generations}; with --resume: the run's, or extend to this many].")] = None,
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
    config: Annotated[Optional[str], typer.Option("--config", metavar="FILE", help="Start a new run from this settings file, in the format of a run's config.toml (a run's own will do); --preset, the options and --set go on top.")] = None,
    print_config: Annotated[bool, typer.Option("--print-config", help="Print the resolved config as TOML (with --config, --from, the options and --set applied) and exit without running.")] = False,
    from_run: Annotated[Optional[str], typer.Option("--from", metavar="RUN[@GENERATION]", help="Start a new run from this run's snapshot of GENERATION (--snapshot-every), or its latest checkpoint, with the options and --set changed; it is recorded as the new run's parent. The scenario, population, tag_length and bt_length stay the parent's [default --logdir: the parent's].")] = None,
    snapshot_every: Annotated[int, typer.Option(help="Keep a copy of the checkpoint every N generations in RUN_DIR/snapshots/ (0: none), to branch from with --from RUN@GENERATION.")] = 0,
    max_time: Annotated[Optional[str], typer.Option(metavar="DURATION", help="Stop cleanly with a checkpoint (resumable) after the generation that ends past this time: 3600 (seconds), 90m, 2h, 1h30m.")] = None,
    patience: Annotated[Optional[int], typer.Option(metavar="K", help="Stop cleanly with a checkpoint (resumable) when the best team has not improved for K generations.")] = None,
    wandb: Annotated[bool, typer.Option("--wandb", help="Also log to Weights & Biases (the scalars, the config, the replays; needs the wandb extra: pip install -e '.[wandb]'; WANDB_MODE=offline for no network).")] = False,
    wandb_project: Annotated[str, typer.Option(help="Weights & Biases project of --wandb.")] = "swarmcode-torch",
) -> None:
    """Evolve a heterogeneous swarm (defaults: the paper's budget experiment)."""
    logdir, resume = check_path(logdir, "--logdir"), check_path(resume, "--resume")
    config_file = check_path(config, "--config")
    wandb_project = _wandb_option(wandb, wandb_project)
    TERMINATED.clear()                    # this command's SIGTERM, not an earlier one's
    bounds = _bounds_option(max_time, patience, snapshot_every)
    if print_config:
        _print_config(config_file, from_run, resume, preset, settings, generations=generations,
                      device=device, scenario=scenario, budget=budget,
                      objective=_objective(objective), population=population,
                      swarm_size=swarm_size, trials=trials, ticks=ticks, seed=seed,
                      compile=compile)
        return
    set_threads_option(threads)
    shards = eval_shards_option(eval_workers, cpus_per_eval_worker, ray_address)
    where = Where()
    with terminate_as_interrupt() as terminated:
        try:
            with ExitStack() as stack:
                attach = None if shards is None else (lambda ev: attach_shards(stack, ev, *shards))
                ev, run_dir, saved = _start_evolve(
                    stack, scenario=scenario, budget=budget, objective=_objective(objective),
                    generations=generations, population=population, swarm_size=swarm_size,
                    trials=trials, ticks=ticks, seed=seed, device=device, compile=compile,
                    logdir=logdir, checkpoint_every=checkpoint_every, log_every=log_every,
                    render_every=render_every, resume=resume, settings=settings, attach=attach,
                    figure_every=figure_every, where=where, preset=preset,
                    config_file=config_file, from_run=from_run)
                if ev is None:
                    return
                execute(ev, run_dir, checkpoint_every, log_every, render_every, saved=saved,
                        figure_every=figure_every, where=where, snapshot_every=snapshot_every,
                        bounds=bounds, wandb_project=wandb_project)
                if shards is not None:
                    print_shard_traffic(ev.ctx.evaluator)
            if bounds is not None and bounds.reason is not None:
                console.print(_bound_line(bounds, ev, run_dir), markup=False, highlight=False,
                              soft_wrap=True)
            else:
                console.print(f"Done: {ev.state.generation} generations in "
                              f"{escape(str(run_dir))}", soft_wrap=True)
            print_team(run_dir)
            # commands and paths are never wrapped (soft_wrap): each stays one line to copy
            console.print(f"Inspect: swarmcode-torch inspect {run_dir}", markup=False,
                          highlight=False, soft_wrap=True)
            console.print(f"Watch: tensorboard --logdir {run_dir.parent}", markup=False,
                          highlight=False, soft_wrap=True)
        except KeyboardInterrupt:
            stopped(where, bool(terminated))


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


def _bounds_option(max_time: str | None, patience: int | None, snapshot_every: int):
    """The run's `session.Bounds` (None without --max-time and --patience); one-line errors."""
    if snapshot_every < 0:
        fail(f"--snapshot-every must be >= 0 (0: no snapshots), got {snapshot_every}")
    if max_time is None and patience is None:
        return None
    if patience is not None and patience < 1:
        fail(f"--patience must be >= 1 (generations without a better best team), got {patience}")
    try:
        return session.Bounds(max_time=max_time, patience=patience)
    except ValueError as e:
        fail(f"--{e}".replace("--max_time", "--max-time"))


def _bound_line(bounds, ev, run_dir: Path) -> str:
    """What a run stopped by --max-time or --patience prints."""
    g = ev.state.generation
    if bounds.reason == "patience":
        why = (f"the best team (generation {ev.state.best['generation']}) has not improved for "
               f"{bounds.patience} generations (--patience {bounds.patience})")
    else:
        why = f"--max-time reached ({bounds.elapsed:.1f}s of {bounds.max_time:g}s)"
    return (f"Stopped after {g} generations: {why}; checkpoint of generation {g} is in "
            f"{run_dir}; continue with: swarmcode-torch evolve --resume {run_dir}")


def _new_config(config_file: Path | None, from_run: str | None, preset, settings, **given):
    """(the config of a new run: --config FILE or the preset, or the --from run's, with
    --preset, the options and --set on top; the `checkpoints.Branch` of --from, or None)."""
    from .checkpoints import load_branch, parse_run_ref
    from .runconfig import read_config_file
    from .settings import option_names

    branch = None
    if from_run is not None:
        if config_file is not None:
            fail("--config and --from cannot be used together: a branch starts from its "
                 "parent's config (give the changes as options and --set)")
        run, generation = parse_run_ref(from_run)
        check_path(str(run), "--from")
        branch = load_branch(run, generation)
        if branch.config.fitness_function is not None:
            fail(f"{run} was scored by a custom fitness function "
                 f"({branch.config.fitness_function}): branch it from Python, "
                 "swarmcode_torch.evolve(from_run=..., fitness=fn)")
        base = branch.config
    elif config_file is not None:
        base = read_config_file(config_file)
        if base.fitness_function is not None:
            fail(f"{config_file}: fitness_function: a fitness function is given from Python "
                 "(swarmcode_torch.evolve(config=FILE, fitness=fn))")
    else:
        return session.resolve_config(preset, settings, **given), None
    if preset is not None:
        base = session.make_config(base, preset=preset)
    names = option_names()
    return replace(with_overrides(base, **given), **parse_settings(settings or [], names)), branch


def _print_config(config_file, from_run, resume, preset, settings, **given) -> None:
    """--print-config: the resolved config of a new run (checked), as TOML, on stdout."""
    from .files import RunError
    from .runconfig import config_to_toml
    from .settings import option_names

    if resume is not None:
        fail("--print-config is for a new run; a resumed run's config is its config.toml")
    try:
        cfg, branch = _new_config(config_file, from_run, preset, settings, **given)
        if branch is None:
            session.check_start(cfg, names=option_names())
        else:
            session.check_branch(branch, cfg, option_names())
            cfg.validate(option_names())
    except (ScenarioError, RunError, ValueError) as e:
        fail(str(e))
    except OSError as e:
        os_fail(e, "cannot read the config")
    sys.stdout.write(config_to_toml(cfg, parent=branch.parent if branch else None))
    sys.stdout.flush()


def _start_evolve(stack: ExitStack, *, scenario, budget, objective, generations, population,
                  swarm_size, trials, ticks, seed, device, compile, logdir, checkpoint_every,
                  log_every, render_every, resume, settings, attach=None, figure_every=50,
                  where: Where, preset=None, config_file=None, from_run=None):
    """Check the options, then make (or lock and reopen) the run directory: (Evolution, run
    directory, generation of its checkpoint), or (None, ...) when a resume has nothing to do.
    The run directory's lock is held until `stack` closes. `attach(ev)`, if given, is called
    once the Evolution exists and before any file is written (evaluation shards)."""
    from .files import RunError, new_run_dir
    from .settings import option_names

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
            extra += ["config"] if config_file is not None else []
            extra += ["from"] if from_run is not None else []
            if extra:
                fail(f"--resume uses the run's saved config; only --generations and --device may "
                     f"change (got --{', --'.join(extra)})")
            if logdir is not None:
                fail(f"--logdir cannot be used with --resume: the run continues in its own "
                     f"directory ({resume})")
            if not resume.is_dir():
                fail(f"--resume {resume} is not a run directory (no such directory)")

            def locked(run_dir: Path) -> None:
                where.run_dir, where.resuming = run_dir, True

            def loaded(saved: int) -> None:
                where.saved = saved

            start = session.start_resume(stack, resume, generations=generations, device=device,
                                         stop_if_done=True, on_locked=locked, on_loaded=loaded,
                                         attach=attach)
            if start.ev is None:
                console.print(f"{resume} already has {start.saved} generations"
                              f"{'' if generations is None else f' (asked for {generations})'}; "
                              "nothing to do, no file changed", markup=False, highlight=False,
                              soft_wrap=True)
                return None, resume, None
            ev = start.ev
            console.print(f"Resuming [bold]{escape(str(resume))}[/] at generation "
                          f"{ev.state.generation} of {ev.cfg.generations}", soft_wrap=True)
            return ev, resume, start.saved
        cfg, branch = _new_config(config_file, from_run, preset, settings,
                                  generations=generations, device=device, **given)
        if logdir is None:      # a branch goes beside its parent
            logdir = branch.run_dir.parent if branch is not None else Path("runs")

        def check_logdir() -> None:        # after the config's checks, before the Evolution
            if logdir.exists() and not logdir.is_dir():
                fail(f"--logdir {logdir} is not a directory")

        def make_dir(ev) -> Path:
            try:
                return new_run_dir(logdir, cfg)
            except OSError as e:
                os_fail(e, f"--logdir {logdir}: cannot make a run directory")

        on_dir = lambda run_dir: setattr(where, "run_dir", run_dir)  # noqa: E731
        if branch is not None:
            start = session.start_branch(stack, branch, cfg, make_dir, names=option_names(),
                                         before_build=check_logdir, attach=attach, on_dir=on_dir)
            console.print(f"Branching from {escape(str(branch.path))} (generation "
                          f"{branch.generation})", highlight=False)
        else:
            start = session.start_new(stack, cfg, make_dir, names=option_names(),
                                      before_build=check_logdir, attach=attach, on_dir=on_dir)
        ev, run_dir = start.ev, start.run_dir
        console.print(f"Run directory: [bold]{escape(str(run_dir))}[/]  (device {ev.ctx.device}, "
                      f"scenario {escape(ev.ctx.scenario.name)}, population {cfg.population}, "
                      f"swarm {ev.ctx.eval_cfg.swarm_size}, tick {ev.ctx.tick_mode})",
                      soft_wrap=True)
        return ev, run_dir, None
    except (ScenarioError, RunError, ValueError) as e:
        fail(str(e))
    except OSError as e:
        os_fail(e, "cannot start the run")


@app.command()
def sweep(
    budgets: Annotated[str, typer.Option(help="Comma-separated budgets in $.")] = "2500,3000,4000,5000,6000,8000",
    seeds: Annotated[str, typer.Option(help="Comma-separated seeds; one run per budget and seed.")] = "0",
    objective: Annotated[Optional[Objective], typer.Option(help="fitness, or roi: fitness / team cost [default: fitness].")] = None,
    scenario: Annotated[Optional[str], typer.Option(help=f"Scenario [default: {_DEFAULT.scenario}].")] = None,
    generations: Annotated[Optional[int], typer.Option(help=f"Generations per run [default: {_DEFAULT.generations}].")] = None,
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
    from .sweep_run import run_sweep

    run_sweep(budgets, seeds, _objective(objective), scenario, generations, population,
              swarm_size, trials, ticks, device, compile, logdir, out, checkpoint_every,
              log_every, preset, settings, workers, cpus_per_run, gpus_per_run, ray_address,
              threads)

@app.command()
def inspect(run_dir: Annotated[str, typer.Argument(metavar="RUN_DIR", help="A run directory (or a sweep directory: its table and runs).")]) -> None:
    """Show the best team of a run: robots per design, hardware, cost and behavior trees. Given
    a sweep directory, show its table and list its runs."""
    run_dir = check_path(run_dir, "RUN_DIR")
    if not run_dir.is_dir():
        fail(f"{run_dir} is not a directory")
    if _inspect_sweep(run_dir):
        return
    designs = print_team(run_dir)
    _print_lineage(run_dir)
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


def _print_lineage(run_dir: Path) -> None:
    """inspect: the run a branched run started from, and why a run stopped early."""
    from .runconfig import read_parent
    from .summary import read_summary

    parent = read_parent(run_dir)
    if parent is not None:
        console.print(f"Branched from {parent.get('run')} at generation "
                      f"{parent.get('generation')} ({parent.get('checkpoint')})", markup=False,
                      highlight=False, soft_wrap=True)
    stop = read_summary(run_dir).get("stop")
    if isinstance(stop, dict) and stop.get("reason") in ("max_time", "patience"):
        console.print(f"Stopped early by {stop['reason']} at generation {stop.get('generation')}"
                      "; it can be continued with evolve --resume", markup=False,
                      highlight=False)


def _inspect_sweep(path: Path) -> bool:
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
        console.print(f"Table: {path / TABLE_MD}, {path / TABLE_CSV}", markup=False,
                      highlight=False, soft_wrap=True)
    else:
        console.print(f"{path} is a sweep without a table yet: run its sweep command again with "
                      f"--out {path} to finish it and write the table", markup=False,
                      highlight=False, soft_wrap=True)
    console.print(f"Runs ({len(sweep.runs)}):", highlight=False)
    for name, done, total in sweep.runs:
        state = ("no generation recorded" if done is None else
                 f"{done}/{total} generations" if total is not None else f"{done} generations")
        console.print(f"  {name}: {state}", markup=False, highlight=False, soft_wrap=True)
    if sweep.runs:
        console.print(f"Inspect a run: swarmcode-torch inspect {path / sweep.runs[0][0]}",
                      markup=False, highlight=False, soft_wrap=True)
    return True


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

    run_dir = check_path(run_dir, "RUN_DIR")

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

    run_dir, out = check_path(run_dir, "RUN_DIR"), check_path(out, "--out")

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
        os_fail(e, "replay failed")
    console.print(f"Wrote {path}: {'the focal team: ' if html else ''}"
                  f"{m['delivered_individual']:.0f} individual and "
                  f"{m['delivered_collab']:.0f} collaborative deliveries, "
                  f"{m['energy_used']:.1f}% energy used", markup=False, highlight=False,
                  soft_wrap=True)


def main() -> None:
    try:
        app()
    except KeyboardInterrupt:
        # an interrupt outside a run's own handling (while starting, or while a stopped run is
        # closing): no traceback, and the exit status of a stop, never death by SIGINT
        err.print("Interrupted", markup=False, highlight=False)
        sys.exit(143 if TERMINATED else 130)


if __name__ == "__main__":
    main()
