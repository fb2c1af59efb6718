"""The `swarmcode-torch` command line: its commands and options, parsed, and what they print.

The work is done elsewhere: `evolve_start` turns evolve's options into a started run, which
runs through `session` (with `terminal.execute`); `inspect_view` prints what inspect adds;
a sweep through `sweep_run`, the analyses in `analysis`."""

from __future__ import annotations

import json
import sys
from contextlib import ExitStack
from enum import Enum
from typing import Annotated

import typer
from rich import box
from rich.console import Console
from rich.markup import escape
from rich.table import Table
from typer.core import TyperGroup

from ..coevo.config import SwarmCoDeConfig
from ..sim import bt
from ..sim.scenario import ScenarioError, builtin_names, load_scenario
from . import evolve_start
from .inspect_view import capabilities, inspect_sweep, print_lineage
from .signals import TERMINATED, terminate_as_interrupt
from .terminal import (
    THREADS_HELP,
    Where,
    attach_shards,
    check_path,
    console,
    err,
    eval_shards_option,
    execute,
    fail,
    os_fail,
    print_shard_traffic,
    print_team,
    set_threads_option,
    stopped,
)


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
app = typer.Typer(
    add_completion=True,
    no_args_is_help=True,
    cls=_OneLineErrors,
    rich_markup_mode=None,
    help="SwarmCoDe: co-design the behavior trees and hardware of robot swarms.",
)
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


def _objective(value: Objective | None) -> str | None:
    return None if value is None else Objective(value).value


def _print_version(value: bool) -> None:
    if value:
        from .. import __version__

        console.print(f"swarmcode-torch {__version__}", highlight=False)
        raise typer.Exit()


@app.callback()
def _options(
    version: Annotated[
        bool | None,
        typer.Option(
            "--version", callback=_print_version, is_eager=True, help="Print the version and exit."
        ),
    ] = None,
) -> None:
    """SwarmCoDe: co-design the behavior trees and hardware of robot swarms."""


@app.command()
def scenarios() -> None:
    """List the built-in scenarios."""
    t = Table(
        title="Built-in scenarios (use with --scenario NAME, or give a .toml file)",
        box=box.SIMPLE_HEAD,
    )
    rows = []
    for name in builtin_names():
        s = load_scenario(name)
        collab = sum(p.count for p in s.packages if p.kind == "collab")
        rows.append(
            (
                name,
                str(s.num_robots),
                str(s.num_packages - collab),
                str(collab),
                str(s.episode_ticks),
                f"{s.species_overhead:g}",
                s.description,
            )
        )
    for i, col in enumerate(
        ("name", "robots", "packages", "collab", "ticks", "$/species", "description")
    ):
        fixed = i < 6  # every column but the description keeps its full width
        t.add_column(
            col,
            no_wrap=True,
            overflow="ellipsis",
            min_width=max(len(col), *(len(r[i]) for r in rows)) if fixed else None,
        )
    for r in rows:
        t.add_row(*r)
    # on a terminal a description is cut to the window; off one (a pipe, a file) every row is
    # one whole line, however long
    (console if console.is_terminal else Console(width=100_000, highlight=False)).print(t)


@app.command()
def evolve(
    scenario: Annotated[
        str | None,
        typer.Option(
            help=f"Built-in scenario name or a scenario .toml file [default: {_DEFAULT.scenario}]."
        ),
    ] = None,
    budget: Annotated[
        float | None, typer.Option(help="Fabrication budget in $ (default: none, no penalty).")
    ] = None,
    objective: Annotated[
        Objective | None,
        typer.Option(help="fitness, or roi: fitness / team cost [default: fitness]."),
    ] = None,
    generations: Annotated[
        int | None,
        typer.Option(
            help=f"Total generations [default: {_DEFAULT.generations}; with --resume: the run's, or extend to this many]."
        ),
    ] = None,
    population: Annotated[
        int | None, typer.Option(help="Individuals in the population [default: 100].")
    ] = None,
    swarm_size: Annotated[
        int | None, typer.Option(help="Robots per team [default: the scenario's].")
    ] = None,
    trials: Annotated[
        int | None, typer.Option(help="Random environments per team evaluation [default: 3].")
    ] = None,
    ticks: Annotated[
        int | None, typer.Option(help="Episode length in ticks [default: the scenario's].")
    ] = None,
    seed: Annotated[int | None, typer.Option(help="Random seed [default: 0].")] = None,
    device: Annotated[
        str | None,
        typer.Option(
            metavar=DEVICE_METAVAR,
            autocompletion=_complete_device,
            help="Where the run computes: auto (cuda if available), cpu, cuda or cuda:N [default: auto].",
        ),
    ] = None,
    compile: Annotated[
        bool | None,
        typer.Option(
            "--compile/--no-compile",
            help="torch.compile the tick [default: on CUDA, and on CPU for >= 50 generations].",
        ),
    ] = None,
    logdir: Annotated[
        str | None,
        typer.Option(metavar="PATH", help="Directory that holds run directories [default: runs]."),
    ] = None,
    checkpoint_every: Annotated[int, typer.Option(help="Generations between checkpoints.")] = 10,
    log_every: Annotated[
        int, typer.Option(help="Generations between log lines when not on a terminal.")
    ] = 10,
    render_every: Annotated[
        int, typer.Option(help="Generations between replay images in TensorBoard (0: never).")
    ] = 50,
    figure_every: Annotated[
        int,
        typer.Option(
            help="Generations between species-composition figures in TensorBoard (one is also drawn at the end of every run)."
        ),
    ] = 50,
    resume: Annotated[
        str | None, typer.Option(metavar="PATH", help="Continue the run in this directory.")
    ] = None,
    preset: Annotated[
        str | None,
        typer.Option(
            help="Algorithm settings to start from: default, or paper (the paper's text and nothing beyond it); --set goes on top [default: default]."
        ),
    ] = None,
    settings: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            metavar="KEY=VALUE",
            help="Set an algorithm config key, e.g. --set p_tag_flip=0.0625 (repeatable; keys as in the run's config.toml).",
        ),
    ] = None,
    eval_workers: Annotated[
        int,
        typer.Option(
            help="Evaluate each generation in this many shards on Ray actors, one GPU each on CUDA, else CPUs (needs Ray; same results as 1)."
        ),
    ] = 1,
    cpus_per_eval_worker: Annotated[
        float | None,
        typer.Option(
            help="Ray: CPUs (and torch threads) of each evaluation actor on the CPU [default: 1]."
        ),
    ] = None,
    ray_address: Annotated[
        str | None,
        typer.Option(
            help="Ray: join the cluster at auto or HOST:PORT for the evaluation shards [default: start a local one]."
        ),
    ] = None,
    threads: Annotated[int | None, typer.Option(help=THREADS_HELP)] = None,
    config: Annotated[
        str | None,
        typer.Option(
            "--config",
            metavar="FILE",
            help="Start a new run from this settings file, in the format of a run's config.toml (a run's own will do); --preset, the options and --set go on top.",
        ),
    ] = None,
    print_config: Annotated[
        bool,
        typer.Option(
            "--print-config",
            help="Print the resolved config as TOML (with --config, --from, the options and --set applied) and exit without running.",
        ),
    ] = False,
    from_run: Annotated[
        str | None,
        typer.Option(
            "--from",
            metavar="RUN[@GENERATION]",
            help="Start a new run from this run's snapshot of GENERATION (--snapshot-every), or its latest checkpoint, with the options and --set changed; it is recorded as the new run's parent. The scenario, population, tag_length and bt_length stay the parent's [default --logdir: the parent's].",
        ),
    ] = None,
    snapshot_every: Annotated[
        int,
        typer.Option(
            help="Keep a copy of the checkpoint every N generations in RUN_DIR/snapshots/ (0: none), to branch from with --from RUN@GENERATION."
        ),
    ] = 0,
    max_time: Annotated[
        str | None,
        typer.Option(
            metavar="DURATION",
            help="Stop cleanly with a checkpoint (resumable) after the generation that ends past this time: 3600 (seconds), 90m, 2h, 1h30m.",
        ),
    ] = None,
    patience: Annotated[
        int | None,
        typer.Option(
            metavar="K",
            help="Stop cleanly with a checkpoint (resumable) when the best team has not improved for K generations.",
        ),
    ] = None,
    wandb: Annotated[
        bool,
        typer.Option(
            "--wandb",
            help="Also log to Weights & Biases (the scalars, the config, the replays; needs the wandb extra: pip install -e '.[wandb]'; WANDB_MODE=offline for no network).",
        ),
    ] = False,
    wandb_project: Annotated[
        str, typer.Option(help="Weights & Biases project of --wandb.")
    ] = "swarmcode-torch",
) -> None:
    """Evolve a heterogeneous swarm (defaults: the paper's budget experiment)."""
    logdir, resume = check_path(logdir, "--logdir"), check_path(resume, "--resume")
    config_file = check_path(config, "--config")
    wandb_project = evolve_start.wandb_option(wandb, wandb_project)
    TERMINATED.clear()  # this command's SIGTERM, not an earlier one's
    bounds = evolve_start.bounds_option(max_time, patience, snapshot_every)
    if print_config:
        evolve_start.print_config(
            config_file,
            from_run,
            resume,
            preset,
            settings,
            generations=generations,
            device=device,
            scenario=scenario,
            budget=budget,
            objective=_objective(objective),
            population=population,
            swarm_size=swarm_size,
            trials=trials,
            ticks=ticks,
            seed=seed,
            compile=compile,
        )
        return
    set_threads_option(threads)
    shards = eval_shards_option(eval_workers, cpus_per_eval_worker, ray_address)
    where = Where()
    with terminate_as_interrupt() as terminated:
        try:
            with ExitStack() as stack:
                attach = None if shards is None else (lambda ev: attach_shards(stack, ev, *shards))
                ev, run_dir, saved = evolve_start.start_evolve(
                    stack,
                    scenario=scenario,
                    budget=budget,
                    objective=_objective(objective),
                    generations=generations,
                    population=population,
                    swarm_size=swarm_size,
                    trials=trials,
                    ticks=ticks,
                    seed=seed,
                    device=device,
                    compile=compile,
                    logdir=logdir,
                    checkpoint_every=checkpoint_every,
                    log_every=log_every,
                    render_every=render_every,
                    resume=resume,
                    settings=settings,
                    attach=attach,
                    figure_every=figure_every,
                    where=where,
                    preset=preset,
                    config_file=config_file,
                    from_run=from_run,
                )
                if ev is None:
                    return
                execute(
                    ev,
                    run_dir,
                    checkpoint_every,
                    log_every,
                    render_every,
                    saved=saved,
                    figure_every=figure_every,
                    where=where,
                    snapshot_every=snapshot_every,
                    bounds=bounds,
                    wandb_project=wandb_project,
                )
                if shards is not None:
                    print_shard_traffic(ev.ctx.evaluator)
            if bounds is not None and bounds.reason is not None:
                console.print(
                    evolve_start.bound_line(bounds, ev, run_dir),
                    markup=False,
                    highlight=False,
                    soft_wrap=True,
                )
            else:
                console.print(
                    f"Done: {ev.state.generation} generations in {escape(str(run_dir))}",
                    soft_wrap=True,
                )
            print_team(run_dir)
            # commands and paths are never wrapped (soft_wrap): each stays one line to copy
            console.print(
                f"Inspect: swarmcode-torch inspect {run_dir}",
                markup=False,
                highlight=False,
                soft_wrap=True,
            )
            console.print(
                f"Watch: tensorboard --logdir {run_dir.parent}",
                markup=False,
                highlight=False,
                soft_wrap=True,
            )
        except KeyboardInterrupt:
            stopped(where, bool(terminated))


@app.command()
def sweep(
    budgets: Annotated[
        str, typer.Option(help="Comma-separated budgets in $.")
    ] = "2500,3000,4000,5000,6000,8000",
    seeds: Annotated[
        str, typer.Option(help="Comma-separated seeds; one run per budget and seed.")
    ] = "0",
    objective: Annotated[
        Objective | None,
        typer.Option(help="fitness, or roi: fitness / team cost [default: fitness]."),
    ] = None,
    scenario: Annotated[
        str | None, typer.Option(help=f"Scenario [default: {_DEFAULT.scenario}].")
    ] = None,
    generations: Annotated[
        int | None, typer.Option(help=f"Generations per run [default: {_DEFAULT.generations}].")
    ] = None,
    population: Annotated[int | None, typer.Option(help="Population [default: 100].")] = None,
    swarm_size: Annotated[
        int | None, typer.Option(help="Robots per team [default: the scenario's].")
    ] = None,
    trials: Annotated[
        int | None, typer.Option(help="Environments per evaluation [default: 3].")
    ] = None,
    ticks: Annotated[
        int | None, typer.Option(help="Episode length [default: the scenario's].")
    ] = None,
    device: Annotated[
        str | None,
        typer.Option(
            metavar=DEVICE_METAVAR,
            autocompletion=_complete_device,
            help="auto (cuda if available), cpu, cuda or cuda:N [default: auto].",
        ),
    ] = None,
    compile: Annotated[
        bool | None, typer.Option("--compile/--no-compile", help="torch.compile the tick.")
    ] = None,
    logdir: Annotated[
        str | None,
        typer.Option(
            metavar="PATH",
            help="Directory that holds the new sweep directory, sweep-<time>, as evolve's --logdir holds run directories [default: runs].",
        ),
    ] = None,
    out: Annotated[
        str | None,
        typer.Option(
            metavar="PATH",
            help="The sweep directory itself [default: LOGDIR/sweep-<time>]; run again with the same --out to resume.",
        ),
    ] = None,
    checkpoint_every: Annotated[int, typer.Option(help="Generations between checkpoints.")] = 10,
    log_every: Annotated[
        int, typer.Option(help="Generations between log lines off a terminal.")
    ] = 50,
    preset: Annotated[
        str | None,
        typer.Option(help="Algorithm settings to start from, as in evolve [default: default]."),
    ] = None,
    settings: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            metavar="KEY=VALUE",
            help="Set an algorithm config key of every run (repeatable), as in evolve.",
        ),
    ] = None,
    workers: Annotated[
        int, typer.Option(help="Runs at once; > 1 runs them as Ray tasks (needs Ray).")
    ] = 1,
    cpus_per_run: Annotated[
        float | None,
        typer.Option(help="Ray: CPUs (and torch threads) each run reserves [default: 1]."),
    ] = None,
    gpus_per_run: Annotated[
        float | None,
        typer.Option(
            help="Ray: GPUs each run reserves; 0.25 packs four runs on a GPU [default: 0]."
        ),
    ] = None,
    ray_address: Annotated[
        str | None,
        typer.Option(
            help="Ray: join the cluster at auto or HOST:PORT [default: start a local one]; the runs go to Ray."
        ),
    ] = None,
    threads: Annotated[int | None, typer.Option(help=THREADS_HELP)] = None,
) -> None:
    """One evolution per budget (and seed); writes the paper's Table III as Markdown and CSV, and a plot."""
    from .sweep_run import run_sweep

    run_sweep(
        budgets,
        seeds,
        _objective(objective),
        scenario,
        generations,
        population,
        swarm_size,
        trials,
        ticks,
        device,
        compile,
        logdir,
        out,
        checkpoint_every,
        log_every,
        preset,
        settings,
        workers,
        cpus_per_run,
        gpus_per_run,
        ray_address,
        threads,
    )


@app.command()
def inspect(
    run_dir: Annotated[
        str,
        typer.Argument(
            metavar="RUN_DIR", help="A run directory (or a sweep directory: its table and runs)."
        ),
    ],
) -> None:
    """Show the best team of a run: robots per design, hardware, cost and behavior trees. Given
    a sweep directory, show its table and list its runs."""
    run_dir = check_path(run_dir, "RUN_DIR")
    if not run_dir.is_dir():
        fail(f"{run_dir} is not a directory")
    if inspect_sweep(run_dir):
        return
    designs = print_team(run_dir)
    print_lineage(run_dir)
    caps = capabilities(run_dir, designs)
    for i, d in enumerate(designs):
        console.print(f"[bold]species {d['species']}[/] ({d['count']} robots, {d['effector']}):")
        if caps is not None:
            labels, can = caps
            lifts = "; ".join(labels[j] for j in can[i]) or "no package class"
            console.print(f"  lifts: {lifts}", highlight=False, markup=False)
        console.print(bt.format_tree(d["bt"], root=True), highlight=False)
    if caps is not None:
        from ..coevo.dynamics import niche_count

        console.print(
            f"{niche_count(caps[1])} niches (distinct capabilities) in "
            f"{len({d['species'] for d in designs})} species",
            highlight=False,
        )


@app.command()
def dynamics(
    run_dir: Annotated[str, typer.Argument(metavar="RUN_DIR", help="A run directory.")],
    window: Annotated[
        list[str] | None,
        typer.Option(
            help="Generations A:B (from A to before B); repeatable [default: every 100, and the last 50]."
        ),
    ] = None,
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
    t = Table(
        title=f"Species dynamics of {run_dir} (medians over each window)",
        box=box.SIMPLE_HEAD,
        caption="founded, extinct: species a generation (lasting: "
        "founded and alive in 2 generations or more); age, "
        "lifetime: generations; lifetime of the species that died in the window",
    )
    cols = (
        ("from", "from", "{}"),
        ("to", "to", "{}"),
        ("team sp", "team_species", "{:g}"),
        ("pop sp", "population_species", "{:g}"),
        ("niches", "niches", "{:g}"),
        ("founded", "founded_per_generation", "{:.2f}"),
        ("lasting", "founded_lasting_per_generation", "{:.2f}"),
        ("extinct", "extinct_per_generation", "{:.2f}"),
        ("age", "median_age", "{:g}"),
        ("team age", "team_median_age", "{:g}"),
        ("lifetime", "median_lifetime", "{:g}"),
        ("team score", "team_score", "{:.1f}"),
    )
    for name, _, _ in cols:
        t.add_column(name, justify="right", no_wrap=True)
    for st in stats:
        t.add_row(*(fmt.format(st[key]) for _, key, fmt in cols))
    console.print(t)


@app.command()
def replay(
    run_dir: Annotated[str, typer.Argument(metavar="RUN_DIR", help="A run directory.")],
    out: Annotated[
        str | None,
        typer.Option(
            metavar="PATH",
            help="Output file [default: RUN_DIR/team.gif, with --html RUN_DIR/team.html].",
        ),
    ] = None,
    generation: Annotated[
        int | None, typer.Option(help="Replay this generation's best team instead of the run's.")
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the random environment.")] = 0,
    ticks: Annotated[int | None, typer.Option(help="Episode length [default: the run's].")] = None,
    every: Annotated[int, typer.Option(help="Draw every k-th tick (GIF).")] = 2,
    html: Annotated[
        bool,
        typer.Option(
            "--html",
            help="Write an interactive page instead: one self-contained HTML file with the team and its baseline team side by side, every tick, each robot's design and behavior tree.",
        ),
    ] = False,
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
        path, m = replay_run(
            run_dir, out=out, seed=seed, ticks=ticks, every=every, generation=generation, html=html
        )
    except (ScenarioError, RunError, ValueError) as e:
        fail(str(e))
    except OSError as e:
        os_fail(e, "replay failed")
    console.print(
        f"Wrote {path}: {'the focal team: ' if html else ''}"
        f"{m['delivered_individual']:.0f} individual and "
        f"{m['delivered_collab']:.0f} collaborative deliveries, "
        f"{m['energy_used']:.1f}% energy used",
        markup=False,
        highlight=False,
        soft_wrap=True,
    )


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
