"""The Python API: run an evolution from a script or a notebook and get its results back.

    import swarmcode_torch as sc

    result = sc.evolve(scenario="four-niche", generations=20, population=30, seed=0)
    result.best_team["fitness"], result.run_dir
    result.to_pandas()[["fitness/best", "team/species"]].plot()
    result = sc.resume(result.run_dir, generations=40)

`evolve` writes the same run directory as `swarmcode-torch evolve` (config.toml, summary.json,
teams.jsonl, metrics.csv, checkpoint.pt, TensorBoard events), with the same reporters, so the
same config gives the same results; `logdir=None` runs in memory and writes nothing. A
scenario is a built-in name, a path to a scenario TOML file, or a `Scenario` object (kept as the
run directory's scenario.toml, like every run's scenario, so that it can be resumed and
replayed).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Iterable
from contextlib import ExitStack
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..coevo.config import SwarmCoDeConfig
from ..coevo.evaluation import ScoreFn
from ..coevo.evolve import Evolution, GenerationResult
from ..sim.runtime import set_threads
from ..sim.scenario import Scenario
from . import api_checks, api_progress, session
from .checkpoints import load_run
from .files import RunError, new_run_dir
from .optspec import Intervals, Values, api_values, check_values, declare_keywords
from .run_options import EVOLVE_OPTIONS
from .run_record import APP_KEY, app_record
from .session import make_config  # noqa: F401 - the API's, as before


# ------------------------------------------------------------------ scenarios
def _scenario_stem(s: Scenario) -> str:
    """The scenario's name as a file stem (a run directory is named after it)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", s.name).strip("._") or "scenario"


# ------------------------------------------------------------------ results
@dataclass
class RunResult:
    """What a run returns.

    history: one dict per generation of every scalar metric (`generation`, `fitness/best`,
        `species/count`, `team/cost`, ... as in metrics.csv and TensorBoard), oldest first.
    species: one composition record per generation: `{"generation", "population": {species id:
        individuals}, "team": {species id: robots in the best team}}`.
    best_team: the best team of the run (fitness, cost, species, niches, deliveries, energy,
        designs: each design's hardware, behavior tree, count and capability): the team of the
        highest mean over the `reeval_trials` fresh environments each generation's best team
        is re-evaluated on, `fitness` that mean, `reeval` its sd and 95 % interval,
        `single_trial_fitness` its own single evaluation (`app.best_team`).
    run_dir: the run directory, or None for a run in memory.
    config: the run's `SwarmCoDeConfig` (swarm size and episode length pinned).
    scenario: the `Scenario` it ran.
    evolution: the `Evolution` (state and context), None for a run loaded with `load`.
    """

    config: SwarmCoDeConfig
    run_dir: Path | None
    history: list[dict]
    species: list[dict]
    best_team: dict | None
    scenario: Scenario | None = None
    evolution: Evolution | None = field(default=None, repr=False)
    stopped: str | None = None
    """Why the run stopped before its last generation: "max_time", "patience" or "callback"
    (`evolve`'s bounds; `resume` continues it), None when it did not."""

    @property
    def generations(self) -> int:
        """Generations finished."""
        return len(self.species)

    def to_pandas(self):
        """`history` as a pandas DataFrame indexed by generation, one column per metric."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError(
                "RunResult.to_pandas() needs pandas: pip install pandas (or "
                "pip install -e '.[pandas]' in the source tree); RunResult.history "
                "holds the same records as a list of dicts"
            ) from None
        return pd.DataFrame(self.history).set_index("generation")

    def __repr__(self) -> str:
        best = self.best_team or {}
        fit = best.get("fitness")
        text = f"fitness {fit:.2f}, {best.get('species')} species" if fit is not None else "no team"
        where = str(self.run_dir) if self.run_dir is not None else "in memory"
        return (
            f"RunResult({self.config.scenario!r}, {self.generations}/"
            f"{self.config.generations} generations, best team: {text}, {where})"
        )


def file_reporters(
    run_dir: Path, checkpoint_every: int = 10, render_every: int = 50, figure_every: int = 50
) -> list:
    """The reporters that write a run directory, as `swarmcode-torch evolve` runs them:
    summary.json and teams.jsonl, metrics.csv, TensorBoard events (a replay image every
    `render_every` generations, 0: never; the composition figure every `figure_every`) and
    checkpoint.pt every `checkpoint_every` generations and at the end."""
    every = api_checks.declared_intervals(
        checkpoint_every=checkpoint_every, render_every=render_every, figure_every=figure_every
    )
    return _file_reporters(run_dir, every)


def _file_reporters(run_dir: Path, every: Intervals, keep: int = 0) -> list:
    """The reporters that write a run directory (`session.file_reporters`) at `every`, keeping
    the last `keep` checkpoints (`keep`)."""
    return session.file_reporters(
        run_dir,
        every.checkpoint,
        every.render,
        every.figure,
        snapshot_every=every.snapshot,
        keep_checkpoints=keep,
    )


def _result(
    ev: Evolution, run_dir: Path | None, history: list[dict], bounds: session.Bounds | None = None
) -> RunResult:
    best = app_record(ev).best
    return RunResult(
        config=ev.cfg,
        run_dir=run_dir,
        history=history,
        species=list(ev.state.history),
        best_team=dict(best) if best else None,
        scenario=ev.ctx.scenario,
        evolution=ev,
        stopped=bounds.reason if bounds is not None else None,
    )


# ------------------------------------------------------------------ evolve, resume, load
# long: its docstring is the public API's parameter table (the docs' reference); the code is under 80 lines
def evolve(
    config: SwarmCoDeConfig | str | os.PathLike | None = None,
    *,
    reporters: Iterable = (),
    callback: Callable[[GenerationResult], Any] | None = None,
    fitness: ScoreFn | None = None,
    wandb: str | None = None,
    progress: bool | None = None,
    **settings,
) -> RunResult:
    """Run an evolution and return its `RunResult`.

    Ctrl-C in a run with a directory writes the checkpoint of the last finished generation
    (continue with `resume`) and re-raises KeyboardInterrupt.

    Args:
        config: an `SwarmCoDeConfig` to start from (default: `SwarmCoDeConfig()`, the paper's
            budget experiment with the default preset; `preset="paper"` for the paper's algorithm
            with nothing beyond it), or the path of a settings file in the format of a run's
            config.toml (`swarmcode-torch evolve --config FILE`).
        scenario (str | PathLike | Scenario | None): a built-in name, a path to a scenario TOML file, or a `Scenario` object.
        budget (float | None): the team budget in $ (`--budget`); UNSET: the config's, as for every setting.
        objective (str): "fitness" or "roi" (`--objective`).
        generations (int): how many generations (`--generations`).
        population (int): the population size (`--population`).
        swarm_size (int | None): robots per team (`--swarm-size`).
        trials (int): environments per team and generation (`--trials`).
        ticks (int | None): the episode length (`--ticks`).
        seed (int): the run's seed (`--seed`).
        device (str): "cpu" or "cuda" (`--device`).
        compile (bool | None): the compiled tick instead of the fused C++ one on the CPU (`--compile`).
        logdir (str | PathLike | None): where the run directory is created (named as by the CLI,
            `SCENARIO[__bBUDGET][__OBJECTIVE]__SEED__TIME`); None: run in memory, write no file.
        checkpoint_every (int): generations between checkpoints.
        render_every (int): generations between TensorBoard replay images (0: never).
        figure_every (int): generations between composition figures.
        preset (str): "default" or "paper".
        threads (int | None): torch's CPU threads for this process (`sim.runtime.set_threads`; default:
            OMP_NUM_THREADS if set, else the cores less the load average, at least 1).
        from_run (str | PathLike | None): "RUN" or "RUN@GENERATION": start a new run from that run's snapshot of
            GENERATION (or its latest checkpoint), as `swarmcode-torch evolve --from`: `settings`
            change the parent's config (its scenario, population, tag_length and bt_length stay),
            the new run records its parent (config.toml's [parent], summary.json's "parent");
            `logdir` defaults to the parent's folder. A parent scored by a `fitness` function needs
            it again.
        snapshot_every (int): keep a copy of the checkpoint every N generations in the run directory's
            snapshots/ (0: none), to branch from with `from_run`.
        max_time (float | str | None): stop cleanly (checkpoint written, `resume` continues it) after the generation
            that ends past it (seconds, or "90m", "2h", ...); `RunResult.stopped` says so.
        patience (int | None): stop when the best team has not improved for this many generations.
        stop_metric (str | None): early stopping on this metric (`stopping.MetricStop`; needs `patience`): the
            run's best team's "best/fitness" (the default) or a metrics.csv tag such as
            "team/fitness".
        stop_min_delta (float | None): an improvement counts when it exceeds this.
        stop_warmup (int | None): generations before the patience count starts.
        stop_mode (str | None): "max" (the default) or "min".
        keep_checkpoints (int): also keep the last K checkpoints
            (RUN_DIR/checkpoints/generation-NNNNNN.pt) and the one of the run's best team
            (checkpoints/best.pt); 0 (the default): none.
        reporters: more reporters (objects with on_start(ev), on_generation(ev, result),
            on_end(ev)).
        callback: called with each generation's `GenerationResult` (`result.best_fitness`,
            `result.team`, ...; `records.scalars(result)` under the tags); returning True (or a
            non-empty string, the reason) stops the run after that generation, as `patience` does
            (`RunResult.stopped` "callback"; summary.json's "stop" has the reason); any other value
            (None, False) lets it go on.
        fitness: a function `fitness(metrics, cost, cfg) -> Tensor [E]` that scores each
            team-episode instead of the built-in fitness (`evaluation.team_scores`: F_raw times the
            budget penalty, / cost for roi): `metrics` maps names (`fitness.METRIC_KEYS`,
            "energy_used", ...) to [E] tensors, `cost` is the [E] team cost in $, `cfg` the run's
            `EvalConfig` (weights, budget, lam, objective). The marginal gate, the mean over trials
            and the EMA apply to its scores. The run records its name (config.toml's
            `fitness_function`, summary.json's "fitness"), and `resume` needs it again.
        wandb: a Weights & Biases project to log the run to as well (`reporting.WandbReporter`;
            needs the wandb extra, `pip install -e ".[wandb]"`; ImportError saying so before
            anything runs).
        progress: print the run's progress on stdout, a compact line per generation (done count,
            time left, best fitness, species; redrawn in place on a terminal or in a notebook).
            None (the default): on a terminal or in a notebook, not when stdout is a file or a
            pipe; True: always; False: never.
        **settings (Any): any other key of `SwarmCoDeConfig` / a run's config.toml (`delta=0.5`, ...);
            they replace the config's.

    Returns:
        The `RunResult`: config, history, species composition, best team, run directory.

    Raises:
        ValueError: (`ScenarioError` is one) an invalid setting or scenario, before any file is
            written.
    """
    o, settings = api_values(EVOLVE_OPTIONS, settings)
    check_values(o.options.values(), o)
    launch = _launch(o, callback, reporters, fitness, progress, wandb, o.logdir is None)
    set_threads(o.threads)
    scenario = settings.pop("scenario", None)
    if o.from_run is not None:
        return _branch(config, scenario, o, settings, launch)
    return _new(config, scenario, o, settings, launch)


#: evolve's signature shows every keyword it takes: those declared in
#: `run_options.RUN_OPTIONS` (`api=True`) before its own
declare_keywords(evolve, EVOLVE_OPTIONS)


@dataclass
class _Launch:
    """What `evolve` and `resume` check and build from their keywords before a run starts.

    reporters: the caller's reporters as the run adds them: the progress line first, the W&B
    ones last; wandb: the W&B ones (a new run names them after its directory); shown: the
    progress line; bounds: the run's `session.Bounds`; fitness: the user fitness function as
    the run calls it; every: the run's `Intervals`; keep: the checkpoints kept
    (keep_checkpoints)."""

    reporters: list
    wandb: list
    shown: api_progress.Progress | None
    bounds: session.Bounds | None
    fitness: ScoreFn | None
    every: Intervals
    keep: int


def _launch(
    o: Values, callback, reporters, fitness, progress, wandb, in_memory=False, wandb_dir=None
) -> _Launch:
    """The `_Launch` of a run's keywords (`o`: the declared ones, checked), each refused
    (TypeError, ValueError) before any file is written; `in_memory`: the run writes no
    directory, which W&B needs; `wandb_dir`: the directory the W&B reporter is named after, when
    it is known."""
    every = o.intervals(EVOLVE_OPTIONS)
    reporters = api_checks.check_hooks(callback, reporters)
    if wandb is not None and in_memory:
        raise ValueError("wandb needs a run directory for its files: give a logdir")
    wandb_reporters = api_checks.wandb_reporters(wandb, wandb_dir, every.render)
    fitness = api_checks.checked_fitness(fitness)
    bounds = api_checks.run_bounds(
        o.max_time,
        o.patience,
        (o.stop_metric, o.stop_min_delta, o.stop_warmup, o.stop_mode),
        callback,
    )
    shown = api_progress.progress_reporter(progress)
    reporters = [*([shown] if shown else []), *reporters, *wandb_reporters]
    return _Launch(reporters, wandb_reporters, shown, bounds, fitness, every, o.keep_checkpoints)


def _new(config, scenario, o: Values, settings, launch: _Launch) -> RunResult:
    """`evolve` without from_run: a new run of `config` (a config, a settings file's path or
    None) changed by `settings`, on `scenario` (a name, a path, a Scenario or None)."""
    names: dict[str, str] = {}  # a bad value from a settings file is named FILE: key
    if isinstance(config, (str, os.PathLike)):
        from .runconfig import read_config_file_keys

        path, (config, keys) = Path(config), read_config_file_keys(Path(config))
        names = {k: f"{path}: {k}" for k in keys if k not in settings}
    scenario_obj = scenario if isinstance(scenario, Scenario) else None
    if scenario is not None and scenario_obj is None:
        settings["scenario"] = scenario
    cfg = make_config(config, **settings)
    if scenario_obj is not None:
        cfg = replace(cfg, scenario=scenario_obj.name)
    name = cfg if scenario_obj is None else replace(cfg, scenario=_scenario_stem(scenario_obj))
    folder = None if o.logdir is None else api_checks.checked_logdir(o.logdir)
    make_dir = None if folder is None else (lambda ev: new_run_dir(folder, name))
    with ExitStack() as stack:
        start = session.start_new(
            stack, cfg, make_dir, scenario=scenario_obj, fitness=launch.fitness, names=names or None
        )
        return _run_started(start, launch)


def _run_started(start, launch: _Launch) -> RunResult:
    """Run a new or branched run that `session` started (its directory locked by the caller's
    stack), the W&B reporters named after its directory. Its `RunResult`."""
    for r in launch.wandb:  # named after the run directory, if there is one
        r.run_dir = start.run_dir
    history = api_progress.History()  # the callback is `bounds`': it may stop the run
    _run(start.ev, start.run_dir, history, launch)
    return _result(start.ev, start.run_dir, history.rows, launch.bounds)


def _run(ev: Evolution, run_dir: Path | None, history, launch: _Launch) -> None:
    """Run `ev` to its end or a bound with `launch`'s reporters after its file reporters (none
    for a run in memory) and `history`, the progress line closed however the run ends."""
    reps = [] if run_dir is None else _file_reporters(run_dir, launch.every, launch.keep)
    with api_progress.closing(launch.shown):
        session.run(ev, run_dir, [*reps, history, *launch.reporters], bounds=launch.bounds)


def _branch(config, scenario, o: Values, settings, launch: _Launch) -> RunResult:
    """`evolve(from_run=...)`: a new run from a run's snapshot (`session.start_branch`); `o`:
    evolve's own keywords (`optspec.api_values`)."""
    from .checkpoints import load_branch, parse_run_ref

    if config is not None:
        raise ValueError(
            "config and from_run cannot be used together: a branch starts from its "
            "parent's config (give the changes as settings)"
        )
    if isinstance(scenario, Scenario):
        raise ValueError("a branch runs on its parent's scenario; scenario cannot change")
    if scenario is not None:
        settings["scenario"] = scenario
    run, generation = parse_run_ref(os.fspath(o.from_run))
    branch = load_branch(run, generation)
    cfg = make_config(branch.config, **settings)
    logdir = o.logdir
    if logdir == "runs":  # the default: beside the parent
        logdir = branch.run_dir.parent
    folder = None if logdir is None else api_checks.checked_logdir(logdir)
    make_dir = None if folder is None else (lambda ev: new_run_dir(folder, cfg, branch))
    with ExitStack() as stack:
        start = session.start_branch(stack, branch, cfg, make_dir, fitness=launch.fitness)
        return _run_started(start, launch)


def _earlier_rows(run_dir: Path, before: int) -> list[dict]:
    from .files import METRICS_FILE
    from .reporting import read_metrics_csv

    path = Path(run_dir) / METRICS_FILE
    if not path.is_file():
        return []
    return [r for r in read_metrics_csv(path)[0] if r["generation"] < before]


# long: its docstring is the public API's parameter table (the docs' reference); the code is under 80 lines
def resume(
    run_dir: str | os.PathLike,
    generations: int | None = None,
    device: str | None = None,
    *,
    checkpoint_every: int = 10,
    render_every: int = 50,
    figure_every: int = 50,
    reporters: Iterable = (),
    callback: Callable[[GenerationResult], Any] | None = None,
    fitness: ScoreFn | None = None,
    threads: int | None = None,
    snapshot_every: int = 0,
    max_time: float | str | None = None,
    patience: int | None = None,
    wandb: str | None = None,
    progress: bool | None = None,
    stop_metric: str | None = None,
    stop_min_delta: float | None = None,
    stop_warmup: int | None = None,
    stop_mode: str | None = None,
    keep_checkpoints: int = 0,
) -> RunResult:
    """Continue the run in `run_dir` from its checkpoint (as `swarmcode-torch evolve --resume`).

    The keywords `run_options` declares are checked against their declared bounds, as in
    `evolve`.

    Args:
        run_dir: the run directory.
        generations: how many generations in all (default: the run's).
        device: "cpu" or "cuda" (default: the run's).
        checkpoint_every: as in `evolve`.
        render_every: as in `evolve`.
        figure_every: as in `evolve`.
        reporters: as in `evolve`.
        callback: called with each generation's `GenerationResult`; it may stop the run, as in
            `evolve`.
        fitness: the run's own fitness function, for a run started with one (`evolve`).
        threads: as in `evolve`.
        snapshot_every: as in `evolve`.
        max_time: as in `evolve`, counted from this call.
        patience: as in `evolve`.
        wandb: as in `evolve`.
        progress: as in `evolve`.
        stop_metric: as in `evolve`.
        stop_min_delta: as in `evolve`.
        stop_warmup: as in `evolve`.
        stop_mode: as in `evolve`.
        keep_checkpoints: as in `evolve`.

    Returns:
        The `RunResult`; its history has every generation: those before the checkpoint from
        metrics.csv (when the run has one), then this part's.

    Raises:
        RunError: (a ValueError) a directory, config or checkpoint that cannot be used.
    """
    d = api_checks.declared(
        checkpoint_every=checkpoint_every,
        render_every=render_every,
        figure_every=figure_every,
        snapshot_every=snapshot_every,
        threads=threads,
        max_time=max_time,
        patience=patience,
        stop_metric=stop_metric,
        stop_min_delta=stop_min_delta,
        stop_warmup=stop_warmup,
        stop_mode=stop_mode,
        keep_checkpoints=keep_checkpoints,
    )
    launch = _launch(d, callback, reporters, fitness, progress, wandb, wandb_dir=Path(run_dir))
    if generations is not None and (
        not isinstance(generations, int) or isinstance(generations, bool) or generations < 1
    ):
        raise ValueError(
            f"generations must be an integer >= 1 (the total to extend the run "
            f"to), got {generations!r:.40}"
        )
    set_threads(threads)
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunError(f"{run_dir} is not a run directory (no such directory)")
    with ExitStack() as stack:
        start = session.start_resume(
            stack, run_dir, generations=generations, device=device, fitness=launch.fitness
        )
        ev = start.ev
        earlier = _earlier_rows(run_dir, ev.state.generation)
        if ev.done:  # nothing to run: no file changes (as the CLI)
            return _result(ev, run_dir, earlier)
        history = api_progress.History()  # the callback is `bounds`'
        _run(ev, run_dir, history, launch)
    return _result(ev, run_dir, earlier + history.rows, launch.bounds)


def load(run_dir: str | os.PathLike) -> RunResult:
    """The results of a run directory as they stand, without running anything.

    Args:
        run_dir: the run directory.

    Returns:
        The `RunResult`: config, metrics.csv as the history (empty for a run written before
        metrics.csv existed), species composition and best team from the checkpoint; its
        `evolution` is None.
    """
    run_dir = Path(run_dir)
    cfg, ck, scenario = load_run(run_dir)
    best = ck[APP_KEY]["best"]
    return RunResult(
        config=cfg,
        run_dir=run_dir,
        history=_earlier_rows(run_dir, math.inf),
        species=list(ck["history"]),
        best_team=dict(best) if best else None,
        scenario=scenario,
    )
