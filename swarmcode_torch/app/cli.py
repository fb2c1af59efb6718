"""The `swarmcode-torch` command line: its commands and options, parsed, and what they print.

The work is done elsewhere: `evolve_start` turns evolve's options into a started run, which
runs through `session` (with `terminal.execute`); `inspect_view` prints what inspect adds;
a sweep through `sweep_run`, the analyses in `analysis`."""

from __future__ import annotations

import json
import sys
from typing import Annotated

import typer
from rich import box
from rich.console import Console
from rich.markup import escape
from rich.table import Table
from typer.core import TyperGroup

from ..sim import bt
from ..sim.scenario import ScenarioError, builtin_names, load_scenario
from . import evolve_start
from .inspect_view import capabilities, inspect_sweep, print_lineage
from .options import WORLD_OPTIONS, Dynamics, Evaluate, Replay, command
from .optspec import Values, check_values
from .run_options import EVOLVE_OPTIONS, SWEEP_OPTIONS
from .signals import TERMINATED, ignore_stop_signals, stop_once
from .terminal import check_path, console, err, fail, os_fail, print_team


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


def _print_version(value: bool) -> None:
    if value:
        from ..version import __version__

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


def _world(values: Values) -> None:
    knobs = {k: v for k, v in values.items() if v is not None and k != "force"}
    from ..sim import worlds
    from .files import atomic_write_bytes, check_output_path
    from .runs import RunError

    split, index, path = knobs.pop("split", None), knobs.pop("index", None), knobs.pop("out", None)
    path = check_path(path, "--out")
    if path is not None:
        try:
            check_output_path(path)
        except RunError as e:
            fail(str(e))
        if path.exists() and not values.force:
            fail(f"--out {path} exists; give --force to replace it")
    try:
        if split is not None or index is not None:
            if split is None or index is None:
                fail("--split and --index go together: --split train|test --index K")
            if knobs:
                fail(
                    f"--split takes no generator options (got --{next(iter(knobs)).replace('_', '-')})"
                )
            w = worlds.study_world(split.value, index)
        else:
            for key in ("mass", "distance"):
                if key in knobs:
                    lo, _, hi = knobs[key].partition(",")
                    try:
                        knobs[key] = (float(lo), float(hi))
                    except ValueError:
                        fail(f"--{key} expects LO,HI (two numbers), got {knobs[key]!r}")
            if "effectors" in knobs:
                knobs["effectors"] = tuple(e.strip() for e in knobs["effectors"].split(","))
            for key in ("family", "bands"):
                if key in knobs:
                    knobs[key] = knobs[key].value
            w = worlds.generate_world(knobs.pop("seed", 0), **knobs)
    except ValueError as e:
        fail(str(e))
    text = worlds.world_toml(w)
    if path is None:
        typer.echo(text, nl=False)
    else:
        try:
            atomic_write_bytes(path, text.encode("utf-8"))
        except OSError as e:
            os_fail(e, f"cannot write {path}")
        console.print(
            f"Wrote {path}: {w.scenario.name}, {w.niches} niche{'s' if w.niches > 1 else ''}",
            markup=False,
            highlight=False,
            soft_wrap=True,
        )
    lines = []
    for i, share in worlds.needles(w.scenario):
        by = f"{100 * share:.2g} % of" if share else f"none of {worlds.SHARE_DESIGNS}"
        lines.append(
            f"class {i}'s heaviest package is lifted by {by} random designs, a needle evolution "
            f"may never find (--min-lift-share {worlds.NEEDLE_SHARE} draws another world; "
            'docs/WORLDS.md, "Needles")'
        )
    if not w.knobs.get("min_reach"):  # drawn without the reach check: say what it would redraw
        for i, share in worlds.out_of_reach(w.scenario, w.niche_designs):
            lines.append(
                f"niche {i + 1} ({w.niche_designs[i].label}) is out of reach: a full swarm of "
                f"its best design brings home {share:.0%} of its packages an episode "
                f'(--min-reach {worlds.REACH_SHARE} draws another world; docs/WORLDS.md, "Reach")'
            )
    for line in lines:  # on stderr: a printed world stays clean
        err.print(f"Warning: {line}", markup=False, highlight=False, soft_wrap=True)


#: world: its options from `options.WORLD_OPTIONS`
world = app.command("world")(
    command(
        WORLD_OPTIONS,
        _world,
        "world",
        "Generate a world that needs a known number of niches (distinct robot designs) and write "
        "it as a scenario TOML file, or print it (docs/WORLDS.md).",
    )
)


def _evolve(values: Values) -> None:
    evolve_start.evolve_command(values)


def _sweep(values: Values) -> None:
    from .sweep_run import run_sweep

    try:
        check_values(SWEEP_OPTIONS, values, lambda o: o.spelling)
    except (TypeError, ValueError) as e:
        fail(str(e))
    run_sweep(**values.converted())


#: evolve and sweep: their options from `run_options.RUN_OPTIONS`
evolve = app.command("evolve")(
    command(
        EVOLVE_OPTIONS,
        _evolve,
        "evolve",
        "Evolve a heterogeneous swarm (defaults: the paper's budget experiment).",
    )
)
sweep = app.command("sweep")(
    command(
        SWEEP_OPTIONS,
        _sweep,
        "sweep",
        "One evolution per budget (and seed, and --grid setting); writes the paper's Table III "
        "as Markdown and CSV, and a plot.",
    )
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
        n = d["count"]
        robots = f"{n} robot" if n == 1 else f"{n} robots"
        console.print(f"[bold]species {d['species']}[/] ({robots}, {d['effector']}):")
        if caps is not None:
            labels, can = caps
            lifts = "; ".join(labels[j] for j in can[i]) or "no package class"
            console.print(f"  lifts: {lifts}", highlight=False, markup=False)
        # not wrapped by Rich (soft_wrap): a tree nested thousands of levels deep prints at once
        console.print(
            bt.format_tree(d["bt"], root=True), highlight=False, markup=False, soft_wrap=True
        )
    if caps is not None:
        from ..coevo.dynamics import niche_count

        console.print(
            f"{niche_count(caps[1])} niches (distinct capabilities) in "
            f"{len({d['species'] for d in designs})} species",
            highlight=False,
        )


@app.command()
def dynamics(
    run_dir: Dynamics.run_dir, window: Dynamics.window = None, as_json: Dynamics.as_json = False
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
    run_dir: Replay.run_dir,
    out: Replay.out = None,
    generation: Replay.generation = None,
    seed: Replay.seed = 0,
    ticks: Replay.ticks = None,
    every: Replay.every = 2,
    html: Replay.html = False,
    seeds: Replay.seeds = 1,
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
    from .replay_view import replay_progress

    lines: list[str] = []
    try:
        with replay_progress() as progress:
            path, m = replay_run(
                run_dir,
                out=out,
                seed=seed,
                ticks=ticks,
                every=every,
                generation=generation,
                html=html,
                progress=progress,
                report=lines.append,
                seeds=seeds,
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
    for line in lines:  # where the arenas part, who delivered
        console.print(line, markup=False, highlight=False, soft_wrap=True)


@app.command()
def evaluate(
    run_dir: Evaluate.run_dir,
    team: Evaluate.team = None,
    generation: Evaluate.generation = None,
    top: Evaluate.top = None,
    episodes: Evaluate.episodes = 20,
    seed_start: Evaluate.seed_start = 1_000_000,
    scenario: Evaluate.scenario = None,
    ticks: Evaluate.ticks = None,
    json_out: Evaluate.json_out = None,
    device: Evaluate.device = "cpu",
    threads: Evaluate.threads = None,
) -> None:
    """Evaluate a run's team on N fresh seeds, in one batch: fitness (mean, sd, 95 % t
    interval), deliveries per package class, cost, and each design's knock-out contribution."""
    options = dict(locals())
    from .evaluate_view import evaluate_command

    evaluate_command(**options)


def main() -> None:
    # one stop per process: after the first Ctrl-C or SIGTERM, later ones are ignored
    stop_once()
    try:
        app()
    except KeyboardInterrupt:
        # an interrupt outside a run's own handling (while starting, or while a stopped run is
        # closing): no traceback, and the exit status of a stop, never death by SIGINT
        err.print("Interrupted", markup=False, highlight=False)
        sys.exit(143 if TERMINATED else 130)
    finally:
        # the command is over and its exit status stands: a signal while the interpreter exits
        # (after the last line) neither kills the process nor prints a traceback
        ignore_stop_signals()


if __name__ == "__main__":
    main()
