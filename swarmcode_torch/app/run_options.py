"""The options of `swarmcode-torch evolve` and `sweep`, each declared once (`optspec.Opt`): its
name, type, default, bound, help, the config key it sets and the commands that take it. The
command line (`options.command`), the keywords of `swarmcode_torch.evolve` (`api`), the option
spellings of error messages (`settings.option_names`), the `Intervals` and the docs' CLI
reference (made from `--help`) are derived from `RUN_OPTIONS`. To add an option, add its `Opt`
here (and, for sweep, the parameter of the same name to `sweep_run.run_sweep`). Options of the
other commands (replay, evaluate, ...) are in `options`; what the process does with the thread
and Ray options is in `process_options`.

No Typer or Rich here: the Python API imports this module."""

from __future__ import annotations

from enum import Enum

from ..coevo.config import SwarmCoDeConfig
from .optspec import Opt, for_command

#: The defaults --help shows for the options that leave them to the run's config.
_DEFAULT = SwarmCoDeConfig()

THREADS_HELP = (
    "CPU threads of this process [default: OMP_NUM_THREADS if set, else the cores "
    "less the load average, at least 1]."
)


class Objective(str, Enum):
    """--objective: its choices, in --help and in shell completion."""

    fitness = "fitness"
    roi = "roi"


def objective_value(value: Objective | str | None) -> str | None:
    """--objective's value as the config takes it."""
    return None if value is None else Objective(value).value


#: --device: shown in --help as its choices; the value is checked with the run's other settings
#: (`SwarmCoDeConfig.validate`), so that its error reads as theirs.
DEVICE_METAVAR = "[auto|cpu|cuda|cuda:N]"
DEVICES = ("auto", "cpu", "cuda", "cuda:0")


def complete_device(incomplete: str) -> list[str]:
    """Shell completion of --device."""
    return [d for d in DEVICES if d.startswith(incomplete)]


#: --budgets of a sweep of budgets alone (the paper's Table III); a sweep with --grid or
#: --config runs the budget of its config unless --budgets is given.
DEFAULT_BUDGETS = "2500,3000,4000,5000,6000,8000"

EVOLVE, SWEEP = ("evolve",), ("sweep",)
BOTH = ("evolve", "sweep")

#: Every option of evolve and sweep, in the order --help lists them.
RUN_OPTIONS: tuple[Opt, ...] = (
    Opt(
        "budgets",
        str | None,
        help=f"Comma-separated budgets in $ [default: {DEFAULT_BUDGETS}; with --grid or "
        "--config: the config's budget].",
        commands=SWEEP,
    ),
    Opt("seeds", str, "0", "Comma-separated seeds; one run per budget and seed.", commands=SWEEP),
    Opt(
        "scenario",
        str | None,
        help=f"Built-in scenario name or a scenario .toml file [default: {_DEFAULT.scenario}].",
        setting="scenario",
        commands=BOTH,
        variants={"sweep": {"help": f"Scenario [default: {_DEFAULT.scenario}]."}},
        api=True,
        api_type="str | os.PathLike | Scenario | None",
        api_default=None,
    ),
    Opt(
        "budget",
        float | None,
        help="Fabrication budget in $ (default: none, no penalty).",
        setting="budget",
        api=True,
    ),
    Opt(
        "objective",
        Objective | None,
        help="fitness, or roi: fitness / team cost [default: fitness].",
        setting="objective",
        commands=BOTH,
        api=True,
        api_type="str",
        to_value=objective_value,
    ),
    Opt(
        "generations",
        int | None,
        help=f"Total generations [default: {_DEFAULT.generations}; with --resume: the run's, "
        "or extend to this many].",
        setting="generations",
        commands=BOTH,
        variants={"sweep": {"help": f"Generations per run [default: {_DEFAULT.generations}]."}},
        api=True,
        api_type="int",
    ),
    Opt(
        "population",
        int | None,
        help="Individuals in the population [default: 100].",
        setting="population",
        commands=BOTH,
        variants={"sweep": {"help": "Population [default: 100]."}},
        api=True,
        api_type="int",
    ),
    Opt(
        "swarm_size",
        int | None,
        help="Robots per team [default: the scenario's].",
        setting="swarm_size",
        commands=BOTH,
        api=True,
    ),
    Opt(
        "trials",
        int | None,
        help="Random environments per team evaluation [default: 3].",
        setting="trials",
        commands=BOTH,
        variants={"sweep": {"help": "Environments per evaluation [default: 3]."}},
        api=True,
        api_type="int",
    ),
    Opt(
        "ticks",
        int | None,
        help="Episode length in ticks [default: the scenario's].",
        setting="ticks",
        commands=BOTH,
        variants={"sweep": {"help": "Episode length [default: the scenario's]."}},
        api=True,
    ),
    Opt(
        "seed",
        int | None,
        help="Random seed [default: 0].",
        setting="seed",
        api=True,
        api_type="int",
    ),
    Opt(
        "device",
        str | None,
        help="Where the run computes: auto (cuda if available), cpu, cuda or cuda:N "
        "[default: auto].",
        metavar=DEVICE_METAVAR,
        complete=complete_device,
        setting="device",
        commands=BOTH,
        variants={
            "sweep": {"help": "auto (cuda if available), cpu, cuda or cuda:N [default: auto]."}
        },
        api=True,
        api_type="str",
    ),
    Opt(
        "compile",
        bool | None,
        help="torch.compile the Python tick [default: on CUDA; on the CPU the fused C++ tick "
        "runs, and --compile replaces it with the compiled Python tick (also where the C++ "
        "tick cannot be built, for runs of >= 50 generations)].",
        flags=("--compile/--no-compile",),
        setting="compile",
        commands=BOTH,
        variants={"sweep": {"help": "torch.compile the tick."}},
        api=True,
    ),
    Opt(
        "logdir",
        str | None,
        help="Directory that holds run directories [default: runs].",
        metavar="PATH",
        commands=BOTH,
        variants={
            "sweep": {
                "help": "Directory that holds the new sweep directory, sweep-<time>, as "
                "evolve's --logdir holds run directories [default: runs]."
            }
        },
        api=True,
        api_type="str | os.PathLike | None",
        api_default="runs",
    ),
    Opt(
        "out",
        str | None,
        help="The sweep directory itself [default: LOGDIR/sweep-<time>]; run again with the "
        "same --out to resume.",
        metavar="PATH",
        commands=SWEEP,
    ),
    Opt(
        "checkpoint_every",
        int,
        10,
        "Generations between checkpoints.",
        low=1,
        interval="checkpoint",
        commands=BOTH,
        api=True,
    ),
    Opt(
        "log_every",
        int,
        10,
        "Generations between log lines when not on a terminal.",
        low=1,
        interval="log",
        commands=BOTH,
        variants={
            "sweep": {"default": 50, "help": "Generations between log lines off a terminal."}
        },
    ),
    Opt(
        "render_every",
        int,
        50,
        "Generations between replay images in TensorBoard (0: never).",
        low=0,
        zero="never",
        interval="render",
        api=True,
    ),
    Opt(
        "figure_every",
        int,
        50,
        "Generations between species-composition figures in TensorBoard (one is also drawn "
        "at the end of every run).",
        low=1,
        interval="figure",
        api=True,
    ),
    Opt("resume", str | None, help="Continue the run in this directory.", metavar="PATH"),
    Opt(
        "preset",
        str | None,
        help="Algorithm settings to start from: default, or paper (the paper's text and nothing "
        "beyond it); --set goes on top [default: default].",
        commands=BOTH,
        variants={
            "sweep": {"help": "Algorithm settings to start from, as in evolve [default: default]."}
        },
        api=True,
        api_type="str",
        setting="preset",
    ),
    Opt(
        "settings",
        list[str] | None,
        help="Set an algorithm config key, e.g. --set p_tag_flip=0.0625 (repeatable; keys as in "
        "the run's config.toml).",
        flags=("--set",),
        metavar="KEY=VALUE",
        commands=BOTH,
        variants={
            "sweep": {
                "help": "Set an algorithm config key of every run (repeatable), as in evolve."
            }
        },
    ),
    Opt(
        "eval_workers",
        int,
        1,
        "Evaluate each generation in this many shards on Ray actors, one GPU each on CUDA, "
        "else CPUs (needs Ray; same results as 1).",
        low=1,
    ),
    Opt(
        "cpus_per_eval_worker",
        float | None,
        help="Ray: CPUs (and torch threads) of each evaluation actor on the CPU [default: 1].",
    ),
    Opt(
        "workers",
        int,
        1,
        "Runs at once; > 1 runs them as Ray tasks (needs Ray).",
        low=1,
        commands=SWEEP,
    ),
    Opt(
        "cpus_per_run",
        float | None,
        help="Ray: CPUs (and torch threads) each run reserves [default: 1].",
        commands=SWEEP,
    ),
    Opt(
        "gpus_per_run",
        float | None,
        help="Ray: GPUs each run reserves; 0.25 packs four runs on a GPU [default: 0].",
        commands=SWEEP,
    ),
    Opt(
        "ray_address",
        str | None,
        help="Ray: join the cluster at auto or HOST:PORT for the evaluation shards [default: "
        "start a local one].",
        commands=BOTH,
        variants={
            "sweep": {
                "help": "Ray: join the cluster at auto or HOST:PORT [default: start a local "
                "one]; the runs go to Ray."
            }
        },
    ),
    Opt("threads", int | None, help=THREADS_HELP, commands=BOTH, api=True),
    Opt(
        "grid",
        list[str] | None,
        help="Also sweep this setting over these values (repeatable: one run per combination, "
        "budget and seed), e.g. --grid delta=0.3,0.5 --grid population=50,100; keys as in a "
        "run's config.toml.",
        flags=("--grid",),
        metavar="KEY=V1,V2,...",
        commands=SWEEP,
    ),
    Opt(
        "config",
        str | None,
        help="Start a new run from this settings file, in the format of a run's config.toml (a "
        "run's own will do); --preset, the options and --set go on top.",
        flags=("--config",),
        metavar="FILE",
        commands=BOTH,
        variants={
            "sweep": {
                "help": "The runs' settings to start from, in the format of a run's "
                "config.toml, as evolve --config; --preset, the options and --set go on top."
            }
        },
    ),
    Opt(
        "print_config",
        bool,
        False,
        "Print the resolved config as TOML (with --config, --from, the options and --set "
        "applied) and exit without running.",
        flags=("--print-config",),
    ),
    Opt(
        "from_run",
        str | None,
        help="Start a new run from this run's snapshot of GENERATION (--snapshot-every), or its "
        "latest checkpoint, with the options and --set changed; it is recorded as the new run's "
        "parent. The scenario, population, tag_length and bt_length stay the parent's [default "
        "--logdir: the parent's].",
        flags=("--from",),
        metavar="RUN[@GENERATION]",
        api=True,
        api_type="str | os.PathLike | None",
    ),
    Opt(
        "snapshot_every",
        int,
        0,
        "Keep a copy of the checkpoint every N generations in RUN_DIR/snapshots/ (0: none), to "
        "branch from with --from RUN@GENERATION.",
        low=0,
        zero="none",
        interval="snapshot",
        api=True,
    ),
    Opt(
        "max_time",
        str | None,
        help="Stop cleanly with a checkpoint (resumable) after the generation that ends past "
        "this time: 3600 (seconds), 90m, 2h, 1h30m.",
        metavar="DURATION",
        api=True,
        api_type="float | str | None",
    ),
    Opt(
        "patience",
        int | None,
        help="Stop cleanly with a checkpoint (resumable) when the best team has not improved "
        "for K generations.",
        metavar="K",
        low=1,
        api=True,
    ),
    Opt(
        "stop_metric",
        str | None,
        help="--patience watches this metric instead of the best team: best/fitness, or a "
        "metrics.csv column such as team/fitness or fitness/mean [default: best/fitness].",
        metavar="TAG",
        api=True,
    ),
    Opt(
        "stop_min_delta",
        float | None,
        help="--patience counts only improvements of the watched metric by more than X "
        "[default: 0].",
        metavar="X",
        api=True,
    ),
    Opt(
        "stop_warmup",
        int | None,
        help="--patience watches from generation N on (the first N generations are not "
        "counted) [default: 0].",
        metavar="N",
        low=0,
        api=True,
    ),
    Opt(
        "stop_mode",
        str | None,
        help="Whether the watched metric improves upwards (max) or downwards (min) [default: max].",
        metavar="[max|min]",
        api=True,
    ),
    Opt(
        "keep_checkpoints",
        int,
        0,
        "Also keep the last K checkpoints (RUN_DIR/checkpoints/generation-NNNNNN.pt) and the "
        "one that holds the run's best team (checkpoints/best.pt); 0: none.",
        metavar="K",
        low=0,
        zero="none kept",
        api=True,
    ),
    Opt(
        "wandb",
        bool,
        False,
        "Also log to Weights & Biases (the scalars, the config, the replays; needs the wandb "
        "extra: pip install -e '.[wandb]'; WANDB_MODE=offline for no network).",
        flags=("--wandb",),
        commands=BOTH,
        variants={
            "sweep": {
                "help": "Also log each run to Weights & Biases, as evolve --wandb, grouped by "
                "the sweep with tags for its budget and seed."
            }
        },
    ),
    Opt(
        "wandb_project",
        str,
        "swarmcode-torch",
        "Weights & Biases project of --wandb.",
        commands=BOTH,
    ),
)

#: The options of each command, in --help's order.
EVOLVE_OPTIONS = for_command(RUN_OPTIONS, "evolve")
SWEEP_OPTIONS = for_command(RUN_OPTIONS, "sweep")


def option_keys(options: tuple[Opt, ...] | None = None) -> dict[str, str]:
    """{config key: the option that sets it (--population)} of `options` (default:
    `RUN_OPTIONS`): the keys --set refuses."""
    return {o.setting: o.spelling for o in options or RUN_OPTIONS if o.setting is not None}
