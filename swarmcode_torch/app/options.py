"""The options of the `swarmcode-torch` commands, as Typer reads them: one `Annotated` type per
option, grouped by command (`Evolve.population`, `Sweep.budgets`, ...), so that `cli` holds
the commands and what they print."""

from __future__ import annotations

from enum import Enum
from typing import Annotated

import typer

from ..coevo.config import SwarmCoDeConfig
from .terminal import THREADS_HELP

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


def objective_value(value: Objective | None) -> str | None:
    """--objective's value as the config takes it."""
    return None if value is None else Objective(value).value


def complete_device(incomplete: str) -> list[str]:
    """Shell completion of --device."""
    return [d for d in DEVICES if d.startswith(incomplete)]


class Evolve:
    """The options of `swarmcode-torch evolve` (`cli.evolve`)."""

    scenario = Annotated[
        str | None,
        typer.Option(
            help=f"Built-in scenario name or a scenario .toml file [default: {_DEFAULT.scenario}]."
        ),
    ]
    budget = Annotated[
        float | None, typer.Option(help="Fabrication budget in $ (default: none, no penalty).")
    ]
    objective = Annotated[
        Objective | None,
        typer.Option(help="fitness, or roi: fitness / team cost [default: fitness]."),
    ]
    generations = Annotated[
        int | None,
        typer.Option(
            help=f"Total generations [default: {_DEFAULT.generations}; with --resume: the run's, or extend to this many]."
        ),
    ]
    population = Annotated[
        int | None, typer.Option(help="Individuals in the population [default: 100].")
    ]
    swarm_size = Annotated[
        int | None, typer.Option(help="Robots per team [default: the scenario's].")
    ]
    trials = Annotated[
        int | None, typer.Option(help="Random environments per team evaluation [default: 3].")
    ]
    ticks = Annotated[
        int | None, typer.Option(help="Episode length in ticks [default: the scenario's].")
    ]
    seed = Annotated[int | None, typer.Option(help="Random seed [default: 0].")]
    device = Annotated[
        str | None,
        typer.Option(
            metavar=DEVICE_METAVAR,
            autocompletion=complete_device,
            help="Where the run computes: auto (cuda if available), cpu, cuda or cuda:N [default: auto].",
        ),
    ]
    compile = Annotated[
        bool | None,
        typer.Option(
            "--compile/--no-compile",
            help="torch.compile the Python tick [default: on CUDA; on the CPU the fused C++ tick runs, and --compile replaces it with the compiled Python tick (also where the C++ tick cannot be built, for runs of >= 50 generations)].",
        ),
    ]
    logdir = Annotated[
        str | None,
        typer.Option(metavar="PATH", help="Directory that holds run directories [default: runs]."),
    ]
    checkpoint_every = Annotated[int, typer.Option(help="Generations between checkpoints.")]
    log_every = Annotated[
        int, typer.Option(help="Generations between log lines when not on a terminal.")
    ]
    render_every = Annotated[
        int, typer.Option(help="Generations between replay images in TensorBoard (0: never).")
    ]
    figure_every = Annotated[
        int,
        typer.Option(
            help="Generations between species-composition figures in TensorBoard (one is also drawn at the end of every run)."
        ),
    ]
    resume = Annotated[
        str | None, typer.Option(metavar="PATH", help="Continue the run in this directory.")
    ]
    preset = Annotated[
        str | None,
        typer.Option(
            help="Algorithm settings to start from: default, or paper (the paper's text and nothing beyond it); --set goes on top [default: default]."
        ),
    ]
    settings = Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            metavar="KEY=VALUE",
            help="Set an algorithm config key, e.g. --set p_tag_flip=0.0625 (repeatable; keys as in the run's config.toml).",
        ),
    ]
    eval_workers = Annotated[
        int,
        typer.Option(
            help="Evaluate each generation in this many shards on Ray actors, one GPU each on CUDA, else CPUs (needs Ray; same results as 1)."
        ),
    ]
    cpus_per_eval_worker = Annotated[
        float | None,
        typer.Option(
            help="Ray: CPUs (and torch threads) of each evaluation actor on the CPU [default: 1]."
        ),
    ]
    ray_address = Annotated[
        str | None,
        typer.Option(
            help="Ray: join the cluster at auto or HOST:PORT for the evaluation shards [default: start a local one]."
        ),
    ]
    threads = Annotated[int | None, typer.Option(help=THREADS_HELP)]
    config = Annotated[
        str | None,
        typer.Option(
            "--config",
            metavar="FILE",
            help="Start a new run from this settings file, in the format of a run's config.toml (a run's own will do); --preset, the options and --set go on top.",
        ),
    ]
    print_config = Annotated[
        bool,
        typer.Option(
            "--print-config",
            help="Print the resolved config as TOML (with --config, --from, the options and --set applied) and exit without running.",
        ),
    ]
    from_run = Annotated[
        str | None,
        typer.Option(
            "--from",
            metavar="RUN[@GENERATION]",
            help="Start a new run from this run's snapshot of GENERATION (--snapshot-every), or its latest checkpoint, with the options and --set changed; it is recorded as the new run's parent. The scenario, population, tag_length and bt_length stay the parent's [default --logdir: the parent's].",
        ),
    ]
    snapshot_every = Annotated[
        int,
        typer.Option(
            help="Keep a copy of the checkpoint every N generations in RUN_DIR/snapshots/ (0: none), to branch from with --from RUN@GENERATION."
        ),
    ]
    max_time = Annotated[
        str | None,
        typer.Option(
            metavar="DURATION",
            help="Stop cleanly with a checkpoint (resumable) after the generation that ends past this time: 3600 (seconds), 90m, 2h, 1h30m.",
        ),
    ]
    patience = Annotated[
        int | None,
        typer.Option(
            metavar="K",
            help="Stop cleanly with a checkpoint (resumable) when the best team has not improved for K generations.",
        ),
    ]
    stop_metric = Annotated[
        str | None,
        typer.Option(
            metavar="TAG",
            help="--patience watches this metric instead of the best team: best/fitness, or a metrics.csv column such as team/fitness or fitness/mean [default: best/fitness].",
        ),
    ]
    stop_min_delta = Annotated[
        float | None,
        typer.Option(
            metavar="X",
            help="--patience counts only improvements of the watched metric by more than X [default: 0].",
        ),
    ]
    stop_warmup = Annotated[
        int | None,
        typer.Option(
            metavar="N",
            help="--patience watches from generation N on (the first N generations are not counted) [default: 0].",
        ),
    ]
    stop_mode = Annotated[
        str | None,
        typer.Option(
            metavar="[max|min]",
            help="Whether the watched metric improves upwards (max) or downwards (min) [default: max].",
        ),
    ]
    keep_checkpoints = Annotated[
        int,
        typer.Option(
            metavar="K",
            help="Also keep the last K checkpoints (RUN_DIR/checkpoints/generation-NNNNNN.pt) and the one that holds the run's best team (checkpoints/best.pt); 0: none.",
        ),
    ]
    wandb = Annotated[
        bool,
        typer.Option(
            "--wandb",
            help="Also log to Weights & Biases (the scalars, the config, the replays; needs the wandb extra: pip install -e '.[wandb]'; WANDB_MODE=offline for no network).",
        ),
    ]
    wandb_project = Annotated[str, typer.Option(help="Weights & Biases project of --wandb.")]


class Sweep:
    """The options of `swarmcode-torch sweep` (`cli.sweep`)."""

    budgets = Annotated[
        str | None,
        typer.Option(
            help="Comma-separated budgets in $ [default: 2500,3000,4000,5000,6000,8000; with --grid or --config: the config's budget]."
        ),
    ]
    seeds = Annotated[str, typer.Option(help="Comma-separated seeds; one run per budget and seed.")]
    objective = Annotated[
        Objective | None,
        typer.Option(help="fitness, or roi: fitness / team cost [default: fitness]."),
    ]
    scenario = Annotated[str | None, typer.Option(help=f"Scenario [default: {_DEFAULT.scenario}].")]
    generations = Annotated[
        int | None, typer.Option(help=f"Generations per run [default: {_DEFAULT.generations}].")
    ]
    population = Annotated[int | None, typer.Option(help="Population [default: 100].")]
    swarm_size = Annotated[
        int | None, typer.Option(help="Robots per team [default: the scenario's].")
    ]
    trials = Annotated[int | None, typer.Option(help="Environments per evaluation [default: 3].")]
    ticks = Annotated[int | None, typer.Option(help="Episode length [default: the scenario's].")]
    device = Annotated[
        str | None,
        typer.Option(
            metavar=DEVICE_METAVAR,
            autocompletion=complete_device,
            help="auto (cuda if available), cpu, cuda or cuda:N [default: auto].",
        ),
    ]
    compile = Annotated[
        bool | None, typer.Option("--compile/--no-compile", help="torch.compile the tick.")
    ]
    logdir = Annotated[
        str | None,
        typer.Option(
            metavar="PATH",
            help="Directory that holds the new sweep directory, sweep-<time>, as evolve's --logdir holds run directories [default: runs].",
        ),
    ]
    out = Annotated[
        str | None,
        typer.Option(
            metavar="PATH",
            help="The sweep directory itself [default: LOGDIR/sweep-<time>]; run again with the same --out to resume.",
        ),
    ]
    checkpoint_every = Annotated[int, typer.Option(help="Generations between checkpoints.")]
    log_every = Annotated[int, typer.Option(help="Generations between log lines off a terminal.")]
    preset = Annotated[
        str | None,
        typer.Option(help="Algorithm settings to start from, as in evolve [default: default]."),
    ]
    settings = Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            metavar="KEY=VALUE",
            help="Set an algorithm config key of every run (repeatable), as in evolve.",
        ),
    ]
    workers = Annotated[
        int, typer.Option(help="Runs at once; > 1 runs them as Ray tasks (needs Ray).")
    ]
    cpus_per_run = Annotated[
        float | None,
        typer.Option(help="Ray: CPUs (and torch threads) each run reserves [default: 1]."),
    ]
    gpus_per_run = Annotated[
        float | None,
        typer.Option(
            help="Ray: GPUs each run reserves; 0.25 packs four runs on a GPU [default: 0]."
        ),
    ]
    ray_address = Annotated[
        str | None,
        typer.Option(
            help="Ray: join the cluster at auto or HOST:PORT [default: start a local one]; the runs go to Ray."
        ),
    ]
    threads = Annotated[int | None, typer.Option(help=THREADS_HELP)]
    grid = Annotated[
        list[str] | None,
        typer.Option(
            "--grid",
            metavar="KEY=V1,V2,...",
            help="Also sweep this setting over these values (repeatable: one run per combination, budget and seed), e.g. --grid delta=0.3,0.5 --grid population=50,100; keys as in a run's config.toml.",
        ),
    ]
    config = Annotated[
        str | None,
        typer.Option(
            "--config",
            metavar="FILE",
            help="The runs' settings to start from, in the format of a run's config.toml, as evolve --config; --preset, the options and --set go on top.",
        ),
    ]


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


class Worlds:
    """The options of `swarmcode-torch world` (`cli.world`, `sim.worlds.generate_world`); the
    generator's options default to None so that --split can refuse them."""

    seed = Annotated[
        int | None,
        typer.Option(
            help="Generator seed: the same seed and options give the same file [default: 0]."
        ),
    ]
    niches = Annotated[
        int | None,
        typer.Option(help="Niches, 1-6: the distinct robot designs the world needs [default: 3]."),
    ]
    family = Annotated[
        WorldFamily | None,
        typer.Option(
            help="classes: one package class per niche; generalist: plus a class two niches lift; collab: plus a collaborative class; single: classes one design lifts (1 niche) [default: classes]."
        ),
    ]
    effectors = Annotated[
        str | None,
        typer.Option(
            metavar="LIST",
            help="Comma-separated effectors of the niches [default: pincher,suction].",
        ),
    ]
    bands = Annotated[
        WorldBands | None,
        typer.Option(
            help="Radius bands of one effector's niches: disjoint, or overlapping (told apart by mass; give --mass up to ~120) [default: disjoint]."
        ),
    ]
    mass = Annotated[
        str | None, typer.Option(metavar="LO,HI", help="Package masses in kg [default: 2,24].")
    ]
    distance = Annotated[
        str | None,
        typer.Option(
            metavar="LO,HI", help="Package distances from the base centre in m [default: 3,9.5]."
        ),
    ]
    inversion = Annotated[
        bool | None,
        typer.Option(
            "--inversion/--no-inversion",
            help="Heavy packages far from the base instead of near it [default: near].",
        ),
    ]
    obstacles = Annotated[int | None, typer.Option(help="Obstacles [default: 4].")]
    num_robots = Annotated[int | None, typer.Option(help="Robots in a team [default: 20].")]
    packages = Annotated[
        int | None, typer.Option(help="Packages in all, shared among the classes [default: 16].")
    ]
    budget = Annotated[
        float | None,
        typer.Option(
            help="Fabrication budget in $ the world is drawn for: refused when no team with one robot per niche fits it; written in the file's header (pass it to evolve --budget) [default: none]."
        ),
    ]
    species_overhead = Annotated[
        float | None, typer.Option(help="$ per distinct species in a team [default: 0].")
    ]
    episode_ticks = Annotated[int | None, typer.Option(help="Episode length [default: 200].")]
    arena = Annotated[float | None, typer.Option(help="Side of the arena in m [default: 20].")]
    base_radius = Annotated[float | None, typer.Option(help="Base radius in m [default: 1.5].")]
    name = Annotated[
        str | None, typer.Option(help="Scenario name [default: world-FAMILY-Nn-SEED].")
    ]
    split = Annotated[
        WorldSplit | None,
        typer.Option(
            help="Write standard study world --index of this split instead (train: seeds 1000-1999, test: 5000-5999; docs/WORLDS.md)."
        ),
    ]
    index = Annotated[
        int | None, typer.Option(metavar="K", help="Which study world of --split, 0-14.")
    ]
    out = Annotated[
        str | None,
        typer.Option(
            metavar="PATH", help="Write the scenario TOML to this file [default: print it]."
        ),
    ]
    force = Annotated[bool, typer.Option("--force", help="Replace an existing --out file.")]
