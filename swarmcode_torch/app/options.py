"""The options of the `swarmcode-torch` commands, as Typer reads them. Those of evolve and
sweep are declared once, in `run_options.RUN_OPTIONS`, and world's in `WORLD_OPTIONS`, each
made into a command by `command`; the other commands' are one `Annotated` type per option,
grouped by command (`Replay.seed`, ...), so that `cli` holds the commands and what they print."""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterable
from enum import Enum
from typing import Annotated, Any

import typer

from .optspec import Opt, Values
from .run_options import (  # noqa: F401 - the command line's names, as before
    DEVICE_METAVAR,
    DEVICES,
    THREADS_HELP,
    Objective,
    complete_device,
    objective_value,
)


def typer_option(o: Opt) -> Any:
    """The `Annotated` type Typer reads for the option `o`."""
    info = typer.Option(*o.flags, help=o.help, metavar=o.metavar, autocompletion=o.complete)
    return Annotated[o.type, info]


def command(
    options: Iterable[Opt], body: Callable[[Values], None], name: str, doc: str
) -> Callable[..., None]:
    """A Typer command function named `name` with one keyword per option of `options` (its
    type, default and help from the declaration) that calls `body` with their `Values`;
    `doc`: its help."""
    options = tuple(options)

    def run(**given: Any) -> None:
        body(Values(options, given))

    params = [
        inspect.Parameter(
            o.name, inspect.Parameter.KEYWORD_ONLY, default=o.default, annotation=typer_option(o)
        )
        for o in options
    ]
    run.__signature__ = inspect.Signature(params)  # type: ignore[attr-defined]
    run.__annotations__ = {p.name: p.annotation for p in params}
    run.__name__ = run.__qualname__ = name
    run.__doc__ = doc
    return run


class Dynamics:
    """The options of `swarmcode-torch dynamics` (`cli.dynamics`)."""

    run_dir = Annotated[str, typer.Argument(metavar="RUN_DIR", help="A run directory.")]
    window = Annotated[
        list[str] | None,
        typer.Option(
            help="Generations A:B (from A to before B); repeatable [default: every 100, and the last 50]."
        ),
    ]
    as_json = Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")]


class Replay:
    """The options of `swarmcode-torch replay` (`cli.replay`)."""

    run_dir = Annotated[str, typer.Argument(metavar="RUN_DIR", help="A run directory.")]
    out = Annotated[
        str | None,
        typer.Option(
            metavar="PATH",
            help="Output file [default: RUN_DIR/team.gif, with --html RUN_DIR/team.html].",
        ),
    ]
    generation = Annotated[
        int | None, typer.Option(help="Replay this generation's best team instead of the run's.")
    ]
    seed = Annotated[int, typer.Option(help="Seed of the random environment.")]
    ticks = Annotated[int | None, typer.Option(help="Episode length [default: the run's].")]
    every = Annotated[int, typer.Option(help="Draw every k-th tick (GIF).")]
    html = Annotated[
        bool,
        typer.Option(
            "--html",
            help="Write an interactive page instead: one self-contained HTML file with the team and its baseline team side by side, every tick, each robot's design and behavior tree.",
        ),
    ]
    seeds = Annotated[
        int,
        typer.Option(
            help="Also score the team and its baseline team in N environments (seeds SEED .. SEED+N-1): the mean marginal contribution, printed and on the page."
        ),
    ]


class EvaluateTeam(str, Enum):
    """evaluate --team: its choices."""

    best = "best"
    last = "last"


class Evaluate:
    """The options of `swarmcode-torch evaluate` (`cli.evaluate`, `evaluate_view`)."""

    run_dir = Annotated[str, typer.Argument(metavar="RUN_DIR", help="A run directory.")]
    team = Annotated[
        EvaluateTeam | None,
        typer.Option(
            help="best: summary.json's best team; last: the last generation's (teams.jsonl) [default: best]."
        ),
    ]
    generation = Annotated[
        int | None,
        typer.Option(metavar="G", help="Evaluate generation G's best team (teams.jsonl)."),
    ]
    top = Annotated[
        int | None,
        typer.Option(
            metavar="K",
            help="Evaluate the K best distinct teams of teams.jsonl by recorded fitness, in one batch.",
        ),
    ]
    episodes = Annotated[
        int, typer.Option(metavar="N", help="Episodes (fresh seeds) per team, 1 to 10000.")
    ]
    seed_start = Annotated[
        int,
        typer.Option(
            metavar="S",
            help="Episode i runs in the environment of seed S + i (replay --seed S + i shows it); the range may not hold the run's own seed.",
        ),
    ]
    scenario = Annotated[
        str | None,
        typer.Option(
            metavar="NAME_OR_PATH",
            help="Evaluate on this scenario (built-in name or .toml file) instead of the run's own; its catalog builds the robots [default: the run's].",
        ),
    ]
    ticks = Annotated[
        int | None,
        typer.Option(help="Episode length [default: the run's; with --scenario, the scenario's]."),
    ]
    json_out = Annotated[
        str | None,
        typer.Option(
            "--json", metavar="FILE", help="Also write the results as JSON to FILE (atomically)."
        ),
    ]
    device = Annotated[
        str,
        typer.Option(
            metavar=DEVICE_METAVAR,
            autocompletion=complete_device,
            help="Where the episodes run: cpu, cuda, cuda:N or auto.",
        ),
    ]
    threads = Annotated[int | None, typer.Option(help=THREADS_HELP)]


class WorldFamily(str, Enum):
    """world --family: its choices (`sim.worlds.FAMILIES`)."""

    classes = "classes"
    generalist = "generalist"
    collab = "collab"
    single = "single"


class WorldBands(str, Enum):
    """world --bands: its choices (`sim.worlds.BAND_MODES`)."""

    disjoint = "disjoint"
    overlapping = "overlapping"


class WorldSplit(str, Enum):
    """world --split: its choices (`sim.worlds.split_seeds`)."""

    train = "train"
    test = "test"


#: The options of `swarmcode-torch world` (`cli.world`, `sim.worlds.generate_world`), in the
#: order --help lists them; the generator's options default to None so that --split can refuse
#: them.
WORLD_OPTIONS: tuple[Opt, ...] = (
    Opt(
        "seed",
        int | None,
        help="Generator seed: the same seed and options give the same file [default: 0].",
    ),
    Opt(
        "niches",
        int | None,
        help="Niches, 1-6: the distinct robot designs the world needs [default: 3].",
    ),
    Opt(
        "family",
        WorldFamily | None,
        help="classes: one package class per niche; generalist: plus a class two niches lift; "
        "collab: plus a collaborative class; single: classes one design lifts (1 niche) "
        "[default: classes].",
    ),
    Opt(
        "effectors",
        str | None,
        help="Comma-separated effectors of the niches [default: pincher,suction].",
        metavar="LIST",
    ),
    Opt(
        "bands",
        WorldBands | None,
        help="Radius bands of one effector's niches: disjoint, or overlapping (told apart by "
        "mass; give --mass up to ~120) [default: disjoint].",
    ),
    Opt("mass", str | None, help="Package masses in kg [default: 2,24].", metavar="LO,HI"),
    Opt(
        "distance",
        str | None,
        help="Package distances from the base centre in m [default: 3,9.5].",
        metavar="LO,HI",
    ),
    Opt(
        "inversion",
        bool | None,
        help="Heavy packages far from the base instead of near it [default: near].",
        flags=("--inversion/--no-inversion",),
    ),
    Opt("obstacles", int | None, help="Obstacles [default: 4]."),
    Opt("num_robots", int | None, help="Robots in a team [default: 20]."),
    Opt("packages", int | None, help="Packages in all, shared among the classes [default: 16]."),
    Opt(
        "budget",
        float | None,
        help="Fabrication budget in $ the world is drawn for: refused when no team with one "
        "robot per niche fits it; written in the file's header (pass it to evolve --budget) "
        "[default: none].",
    ),
    Opt("species_overhead", float | None, help="$ per distinct species in a team [default: 0]."),
    Opt("episode_ticks", int | None, help="Episode length [default: 200]."),
    Opt("arena", float | None, help="Side of the arena in m [default: 20]."),
    Opt("base_radius", float | None, help="Base radius in m [default: 1.5]."),
    Opt("name", str | None, help="Scenario name [default: world-FAMILY-Nn-SEED]."),
    Opt(
        "min_lift_share",
        float | None,
        help="Redraw a world in which a class's heaviest package is lifted by fewer than this "
        "share of random designs, e.g. 0.01 (a needle evolution may never find; "
        "docs/WORLDS.md) [default: 0, no check].",
        metavar="SHARE",
    ),
    Opt(
        "min_reach",
        float | None,
        help="Redraw a world in which a full swarm of a niche's best design brings home fewer "
        "than this share of the niche's packages an episode (a niche the fitness does not ask "
        'for; docs/WORLDS.md, "Reach"); 0: no check [default: 0.5].',
        metavar="SHARE",
    ),
    Opt(
        "split",
        WorldSplit | None,
        help="Write standard study world --index of this split instead (train: seeds "
        "1000-1999, test: 5000-5999; docs/WORLDS.md).",
    ),
    Opt("index", int | None, help="Which study world of --split, 0-14.", metavar="K"),
    Opt(
        "out",
        str | None,
        help="Write the scenario TOML to this file [default: print it].",
        metavar="PATH",
    ),
    Opt("force", bool, False, "Replace an existing --out file.", flags=("--force",)),
)
