"""The `swarmcode-torch` command line: scenarios, evolve, inspect."""

from __future__ import annotations

import json
import signal
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich import box
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from . import bt
from .scenario import ScenarioError, builtin_names, load_scenario

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="SwarmCoDe: co-design the behavior trees and hardware of robot swarms.")
# off a terminal (logs, pipes) Rich would wrap at 80 columns; tables need a little more
console = Console(width=None if sys.stdout.isatty() else 120)
err = Console(stderr=True, width=None if sys.stderr.isatty() else 200)


def fail(msg: str) -> None:
    """Print a one-line error and exit non-zero."""
    err.print(f"[bold red]Error:[/] {msg}", highlight=False, soft_wrap=True)
    raise typer.Exit(code=2)


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
    console.print(t)


class _Progress:
    """Rich progress bar on a terminal; a plain line every few generations otherwise."""

    def __init__(self, total: int, start: int, every: int):
        self.tty = sys.stdout.isatty()
        self.every = every
        self.bar = None
        if self.tty:
            self.bar = Progress(TextColumn("gen"), MofNCompleteColumn(), BarColumn(),
                                TextColumn("{task.description}"), TimeElapsedColumn(),
                                console=console)
            self.task = self.bar.add_task("", total=total, completed=start)

    def on_start(self, ev) -> None:
        if self.bar:
            self.bar.start()

    def on_generation(self, ev, m: dict) -> None:
        text = (f"best {m['fitness/best']:.1f}  species {m['species/count']}  "
                f"team {m['team/species']} sp ${m['team/cost']:.0f}  "
                f"{m['perf/generation_seconds']:.2f}s/gen")
        if self.bar:
            self.bar.update(self.task, completed=ev.state.generation, description=text)
        elif ev.state.generation % self.every == 0 or ev.done:
            print(f"gen {ev.state.generation}/{ev.cfg.generations}  {text}", flush=True)

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
    objective: Annotated[Optional[str], typer.Option(help="'fitness' or 'roi' (fitness / team cost).")] = None,
    generations: Annotated[Optional[int], typer.Option(help="Total generations (with --resume: extend to this many).")] = None,
    population: Annotated[Optional[int], typer.Option(help="Individuals in the population [default: 100].")] = None,
    swarm_size: Annotated[Optional[int], typer.Option(help="Robots per team [default: the scenario's].")] = None,
    trials: Annotated[Optional[int], typer.Option(help="Random environments per team evaluation [default: 3].")] = None,
    ticks: Annotated[Optional[int], typer.Option(help="Episode length in ticks [default: the scenario's].")] = None,
    seed: Annotated[Optional[int], typer.Option(help="Random seed [default: 0].")] = None,
    device: Annotated[Optional[str], typer.Option(help="auto, cpu or cuda [default: auto].")] = None,
    compile: Annotated[Optional[bool], typer.Option("--compile/--no-compile", help="torch.compile the tick [default: on CUDA, and on CPU for >= 50 generations].")] = None,
    logdir: Annotated[Path, typer.Option(help="Directory that holds run directories.")] = Path("runs"),
    checkpoint_every: Annotated[int, typer.Option(help="Generations between checkpoints.")] = 10,
    log_every: Annotated[int, typer.Option(help="Generations between log lines when not on a terminal.")] = 10,
    render_every: Annotated[int, typer.Option(help="Generations between replay images in TensorBoard (0: never).")] = 50,
    resume: Annotated[Optional[Path], typer.Option(help="Continue the run in this directory.")] = None,
    settings: Annotated[Optional[list[str]], typer.Option("--set", metavar="KEY=VALUE", help="Set an algorithm config key, e.g. --set p_tag_flip=0.0625 (repeatable; keys as in the run's config.toml).")] = None,
) -> None:
    """Evolve a heterogeneous swarm (defaults: the paper's budget experiment)."""
    from .evolve import Evolution, EvolveConfig, parse_settings, with_overrides
    from .runs import RunError, new_run_dir, write_config
    from .runs import resume as resume_run

    if checkpoint_every < 1 or log_every < 1 or render_every < 0:
        fail("--checkpoint-every and --log-every must be >= 1, --render-every >= 0")
    given = dict(scenario=scenario, budget=budget, objective=objective, population=population,
                 swarm_size=swarm_size, trials=trials, ticks=ticks, seed=seed, compile=compile)
    try:
        if resume is not None:
            extra = [k.replace("_", "-") for k, v in given.items() if v is not None]
            extra += ["set"] if settings else []
            if extra:
                fail(f"--resume uses the run's saved config; only --generations and --device may "
                     f"change (got --{', --'.join(extra)})")
            ev = resume_run(resume, generations=generations, device=device)
            run_dir = resume
            write_config(run_dir, ev.cfg)
            console.print(f"Resuming [bold]{run_dir}[/] at generation {ev.state.generation} "
                          f"of {ev.cfg.generations}")
        else:
            cfg = with_overrides(EvolveConfig(), generations=generations, device=device, **given,
                                 **parse_settings(settings or []))
            cfg.validate()
            if cfg.scenario:
                load_scenario(cfg.scenario)  # a clear error before anything is created
            ev = Evolution(cfg)
            run_dir = new_run_dir(logdir, cfg)
            write_config(run_dir, ev.cfg)
            console.print(f"Run directory: [bold]{run_dir}[/]  (device {ev.ctx.device}, "
                          f"scenario {ev.ctx.scenario.name}, population {cfg.population}, "
                          f"swarm {ev.ctx.eval_cfg.swarm_size}, tick {ev.ctx.tick_mode})")
    except (ScenarioError, RunError, ValueError) as e:
        fail(str(e))

    _execute(ev, run_dir, checkpoint_every, log_every, render_every)
    console.print(f"Done: {ev.state.generation} generations in {run_dir}")
    _print_team(run_dir)
    console.print(f"Inspect: swarmcode-torch inspect {run_dir}   Watch: tensorboard --logdir {run_dir.parent}")


def _execute(ev, run_dir: Path, checkpoint_every: int, log_every: int,
             render_every: int = 0) -> None:
    """Run `ev` to its last generation with progress, summary, TensorBoard and checkpoints."""
    from .reporting import TensorBoardReporter
    from .runs import CheckpointReporter, SummaryReporter, run

    progress = _Progress(ev.cfg.generations, ev.state.generation, log_every)
    reporters = [progress, SummaryReporter(run_dir),
                 TensorBoardReporter(run_dir, render_every=render_every),
                 CheckpointReporter(run_dir, checkpoint_every)]
    terminated: list[int] = []
    try:
        with _terminate_as_interrupt() as terminated:
            run(ev, run_dir, reporters)
    except KeyboardInterrupt:
        progress.stop()
        how = "Terminated" if terminated else "Interrupted"
        err.print(f"{how}: checkpoint of generation {ev.state.generation} written to "
                  f"{run_dir}; continue with: swarmcode-torch evolve --resume {run_dir}")
        raise typer.Exit(code=143 if terminated else 130)
    progress.stop()


@contextmanager
def _terminate_as_interrupt():
    """Within the block SIGTERM (a scheduler's or `kill`'s stop) acts as Ctrl-C: the run writes
    the checkpoint of its last finished generation. Yields a list that is non-empty once
    SIGTERM has arrived."""
    terminated: list[int] = []

    def handler(signum, frame):
        terminated.append(signum)
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
    return vals


@app.command()
def sweep(
    budgets: Annotated[str, typer.Option(help="Comma-separated budgets in $.")] = "2500,3000,4000,5000,6000,8000",
    seeds: Annotated[str, typer.Option(help="Comma-separated seeds; one run per budget and seed.")] = "0",
    objective: Annotated[Optional[str], typer.Option(help="'fitness' or 'roi'.")] = None,
    scenario: Annotated[Optional[str], typer.Option(help="Scenario [default: budget].")] = None,
    generations: Annotated[Optional[int], typer.Option(help="Generations per run [default: 500].")] = None,
    population: Annotated[Optional[int], typer.Option(help="Population [default: 100].")] = None,
    swarm_size: Annotated[Optional[int], typer.Option(help="Robots per team [default: the scenario's].")] = None,
    trials: Annotated[Optional[int], typer.Option(help="Environments per evaluation [default: 3].")] = None,
    ticks: Annotated[Optional[int], typer.Option(help="Episode length [default: the scenario's].")] = None,
    device: Annotated[Optional[str], typer.Option(help="auto, cpu or cuda.")] = None,
    compile: Annotated[Optional[bool], typer.Option("--compile/--no-compile", help="torch.compile the tick.")] = None,
    out: Annotated[Optional[Path], typer.Option(help="Sweep directory; run again with the same --out to resume.")] = None,
    checkpoint_every: Annotated[int, typer.Option(help="Generations between checkpoints.")] = 10,
    log_every: Annotated[int, typer.Option(help="Generations between log lines off a terminal.")] = 50,
    settings: Annotated[Optional[list[str]], typer.Option("--set", metavar="KEY=VALUE", help="Set an algorithm config key of every run (repeatable), as in evolve.")] = None,
) -> None:
    """One evolution per budget (and seed); writes the paper's Table III as Markdown and CSV, and a plot."""
    import time

    from .evolve import Evolution, EvolveConfig, parse_settings, with_overrides
    from .runs import RunError, load_checkpoint, read_config, write_config
    from .runs import resume as resume_run
    from .sweep import run_name, table_rows, write_outputs

    budget_list = _parse_list(budgets, float, "--budgets")
    seed_list = _parse_list(seeds, int, "--seeds")
    out = out or Path("runs") / f"sweep-{time.strftime('%Y%m%d-%H%M%S')}"
    try:
        base = with_overrides(EvolveConfig(), objective=objective, scenario=scenario,
                              generations=generations, population=population,
                              swarm_size=swarm_size, trials=trials, ticks=ticks, device=device,
                              compile=compile,
                              **parse_settings(settings or [], {"seed": "--seeds",
                                                                "budget": "--budgets"}))
        for b in budget_list:
            with_overrides(base, budget=b).validate()
        load_scenario(base.scenario)
    except (ScenarioError, ValueError) as e:
        fail(str(e))
    out.mkdir(parents=True, exist_ok=True)
    runs = []
    for b in budget_list:
        for s in seed_list:
            cfg = with_overrides(base, budget=b, seed=s)
            run_dir = out / run_name(b, s)
            try:
                if (run_dir / "config.toml").is_file() and (run_dir / "checkpoint.pt").is_file():
                    if read_config(run_dir).generations >= cfg.generations and \
                            load_checkpoint(run_dir)["generation"] >= cfg.generations:
                        console.print(f"{run_dir.name}: already done")
                        runs.append((b, s, run_dir))
                        continue
                    ev = resume_run(run_dir, generations=cfg.generations)
                else:
                    ev = Evolution(cfg)            # a config error leaves no directory behind
                    run_dir.mkdir(exist_ok=True)
                    write_config(run_dir, ev.cfg)
            except (ScenarioError, RunError, ValueError) as e:
                fail(str(e))
            console.print(f"[bold]{run_dir.name}[/]: generation {ev.state.generation} -> {cfg.generations}")
            _execute(ev, run_dir, checkpoint_every, log_every)
            runs.append((b, s, run_dir))
    rows = table_rows(runs)
    paths = write_outputs(rows, out)
    console.print((out / "table.md").read_text(), highlight=False)
    console.print("Wrote " + ", ".join(str(p) for p in paths))


def _print_team(run_dir: Path) -> None:
    path = Path(run_dir) / "summary.json"
    if not path.is_file():
        fail(f"{run_dir} has no summary.json (is it a run directory with a finished generation?)")
    try:
        s = json.loads(path.read_text())
        designs = s["designs"]
    except (json.JSONDecodeError, KeyError, TypeError):
        fail(f"{path} is malformed")
    budget = "none" if s.get("budget") is None else f"${s['budget']:g}"
    console.print(
        f"Best team (generation {s['best_generation']}): fitness {s['best_fitness']:.2f}, "
        f"cost ${s['team_cost']:.0f} (budget {budget}), {s['num_species']} species, "
        f"deliveries {s['deliveries']:.2f} ({s['deliveries_individual']:.2f} individual, "
        f"{s['deliveries_collab']:.2f} collaborative), energy used {s['energy_used']:.1f}%")
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
def inspect(run_dir: Annotated[Path, typer.Argument(help="A run directory.")]) -> None:
    """Show the best team of a run: robots per design, hardware, cost and behavior trees."""
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
        console.print(bt.format_tree(d["bt"]) or "  (empty tree)", highlight=False)
    if caps is not None:
        from .dynamics import niche_count
        console.print(f"{niche_count(caps[1])} niches (distinct capabilities) in "
                      f"{len({d['species'] for d in designs})} species", highlight=False)


def _capabilities(run_dir: Path, designs: list[dict]):
    """(package class labels, per design the classes it lifts), or None without a scenario."""
    from .analysis import design_capabilities
    from .runs import RunError, read_config

    try:
        scenario = load_scenario(read_config(run_dir).scenario)
        return [c.label for c in scenario.packages], design_capabilities(designs, scenario)
    except (RunError, ValueError):
        return None


@app.command()
def dynamics(
    run_dir: Annotated[Path, typer.Argument(help="A run directory.")],
    window: Annotated[Optional[list[str]], typer.Option(help="Generations A:B (from A to before B); repeatable [default: every 100, and the last 50].")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")] = False,
) -> None:
    """Species dynamics of a run: species in the best team and the population, niches, founding
    and extinction per generation, ages and lifetimes, over windows of generations."""
    from .analysis import run_dynamics
    from .runs import RunError

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
              box=box.SIMPLE_HEAD, caption="founded, extinct: species a generation; age, "
              "lifetime: generations; lifetime of the species that died in the window")
    cols = (("from", "from", "{}"), ("to", "to", "{}"), ("team sp", "team_species", "{:g}"),
            ("pop sp", "population_species", "{:g}"), ("niches", "niches", "{:g}"),
            ("founded", "founded_per_generation", "{:.2f}"),
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
    run_dir: Annotated[Path, typer.Argument(help="A run directory.")],
    out: Annotated[Optional[Path], typer.Option(help="Output GIF [default: RUN_DIR/team.gif].")] = None,
    generation: Annotated[Optional[int], typer.Option(help="Replay this generation's best team instead of the run's.")] = None,
    seed: Annotated[int, typer.Option(help="Seed of the random environment.")] = 0,
    ticks: Annotated[Optional[int], typer.Option(help="Episode length [default: the run's].")] = None,
    every: Annotated[int, typer.Option(help="Draw every k-th tick.")] = 2,
) -> None:
    """Render a rollout of the best team headless, as an animated GIF."""
    from .render import replay_run
    from .runs import RunError

    if every < 1 or (ticks is not None and ticks < 1):
        fail("--every and --ticks must be >= 1")
    if not run_dir.is_dir():
        fail(f"{run_dir} is not a directory")
    try:
        path, m = replay_run(run_dir, out=out, seed=seed, ticks=ticks, every=every,
                             generation=generation)
    except (ScenarioError, RunError, ValueError) as e:
        fail(str(e))
    console.print(f"Wrote {path}: {m['delivered_individual']:.0f} individual and "
                  f"{m['delivered_collab']:.0f} collaborative deliveries, "
                  f"{m['energy_used']:.1f}% energy used")


def main() -> None:
    app()


if __name__ == "__main__":
    main()
