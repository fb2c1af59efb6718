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

import functools
import math
import os
import re
import sys
import time
from collections.abc import Callable, Iterable
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..coevo.config import SwarmCoDeConfig
from ..coevo.evaluation import ScoreFn, score_fn_name
from ..coevo.evolve import Evolution, GenerationResult
from ..sim.runtime import set_threads
from ..sim.scenario import Scenario
from . import records, session
from .checkpoints import load_run
from .files import RunError, new_run_dir
from .optspec import Intervals, Values, api_values, check_values, declare_keywords
from .run_options import EVOLVE_OPTIONS
from .runconfig import scenario_to_toml  # noqa: F401 - the API's, as before
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


class _History:
    """Reporter: collects every generation's scalars (`records.scalars`); calls a user callback
    with each generation's `GenerationResult`."""

    def __init__(self, callback: Callable[[GenerationResult], Any] | None = None):
        self.rows: list[dict] = []
        self.callback = callback

    def on_start(self, ev: Evolution) -> None:
        pass

    def on_generation(self, ev: Evolution, result: GenerationResult) -> None:
        self.rows.append(records.scalars(result))
        if self.callback is not None:
            self.callback(result)

    def on_end(self, ev: Evolution) -> None:
        pass


def _interactive(stream) -> bool:
    """Whether `stream` is shown as it is written: a terminal, or a notebook's output (a Jupyter
    kernel's stream, which is no terminal but redraws a line on a carriage return)."""
    if type(stream).__module__.split(".")[0] == "ipykernel":
        return True
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


def _clock(seconds: float) -> str:
    s = int(round(seconds))
    return (
        f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"
    )


class _Progress:
    """Reporter: the progress of a run on stdout, one compact line per generation (done count,
    time left, best fitness, species, the generation's best team, seconds per generation). On a
    terminal or in a notebook the line is redrawn in place and ended when the run ends;
    elsewhere (a log) each generation prints its own line."""

    def __init__(self):
        self.stream = None
        self.inplace = False
        self.width = 0

    def on_start(self, ev: Evolution) -> None:
        self.stream = sys.stdout
        self.inplace = _interactive(self.stream)
        self.start, self.first, self.width = time.monotonic(), ev.state.generation, 0

    def on_generation(self, ev: Evolution, result: GenerationResult) -> None:
        done, total = ev.state.generation, ev.cfg.generations
        ran = done - self.first
        left = (time.monotonic() - self.start) / ran * (total - done) if ran > 0 else None
        team = result.team
        line = (
            f"done {done}/{total}  left {'?' if left is None else _clock(left)}  best "
            f"{result.best['fitness']:.1f}  species {result.num_species}  team "
            f"{team['species']} sp, {team['niches']} niches, ${team['cost']:.0f}  "
            f"{result.seconds:.2f}s/gen"
        )
        if self.inplace:
            self.stream.write("\r" + line.ljust(self.width))
            self.width = max(self.width, len(line))
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def on_end(self, ev: Evolution) -> None:
        self.close()

    def on_stop(self, ev: Evolution, record: dict) -> None:
        """A bound or the callback stopped the run: a line saying why (`stopping.stop_text`)."""
        from .stopping import stop_text

        self.close()
        self.stream.write(stop_text(record) + "\n")
        self.stream.flush()

    def close(self) -> None:
        """End the line redrawn in place (at the end of a run, or when it stops)."""
        if self.inplace and self.width:
            self.stream.write("\n")
            self.stream.flush()
            self.width = 0


def _progress(progress: bool | None) -> _Progress | None:
    """The progress reporter of `progress`: None (the default) shows it on a terminal or in a
    notebook, True always, False never."""
    if progress is not None and not isinstance(progress, bool):
        raise TypeError(f"progress must be True, False or None, got {progress!r:.40}")
    if progress is False or (progress is None and not _interactive(sys.stdout)):
        return None
    return _Progress()


@contextmanager
def _closing(shown: _Progress | None):
    """The progress line ended however the run ends (a Ctrl-C, an error)."""
    try:
        yield
    finally:
        if shown is not None:
            shown.close()


def _logdir(logdir) -> Path:
    """`logdir` as a folder; RunError for an empty one ('' would write into the working
    directory) or one that is not a path."""
    if not isinstance(logdir, (str, os.PathLike)) or not str(os.fspath(logdir)).strip():
        raise RunError(f"logdir must be a folder path, got {logdir!r:.60}")
    return Path(logdir)


def _declared(**given: Any) -> Values:
    """The API's keywords that `run_options` declares (checkpoint_every=, patience=, ...) as
    `Values`, each checked against its declared bound (`optspec.check_values`): TypeError for
    one that is not an integer, ValueError below its bound."""
    opts = [o for o in EVOLVE_OPTIONS if o.name in given]
    values = Values(opts, given)
    check_values(opts, values)
    return values


def _intervals(**given: Any) -> Intervals:
    """The `Intervals` of the API's keywords (checkpoint_every=, render_every=, ...; the others
    at their defaults), each checked (`_declared`)."""
    return _declared(**given).intervals(EVOLVE_OPTIONS)


def _check_hooks(callback, reporters) -> list:
    """`callback` callable (or None) and every reporter with callable on_start, on_generation
    and on_end: TypeError before any file is written, not a crash mid-run. The reporters as a
    list."""
    if callback is not None and not callable(callback):
        raise TypeError(
            f"callback must be a function of a GenerationResult, got {type(callback).__name__}"
        )
    if isinstance(reporters, (str, bytes)) or not hasattr(reporters, "__iter__"):
        raise TypeError(f"reporters must be a list of reporters, got {type(reporters).__name__}")
    reporters = list(reporters)
    for i, r in enumerate(reporters):
        missing = [
            m for m in ("on_start", "on_generation", "on_end") if not callable(getattr(r, m, None))
        ]
        if missing:
            raise TypeError(
                f"reporters[{i}] ({type(r).__name__}) has no {', '.join(missing)} "
                "method (a reporter has on_start(ev), on_generation(ev, result) and "
                "on_end(ev))"
            )
    return reporters


#: The largest score a user fitness function may return: the mean of a population's scores
#: stays finite in float32 (3.4e38).
MAX_SCORE = 1e30


def _checked_fitness(fitness: ScoreFn | None) -> ScoreFn | None:
    """A user fitness function as a run calls it: with copies of the metrics and the cost (a
    function that edits them in place cannot change what the run records), and its scores
    refused (ValueError) when beyond +-MAX_SCORE, where a mean would overflow. It keeps the
    function's name (`score_fn_name`), which the run records."""
    if fitness is None:
        return None
    if not callable(fitness):
        raise TypeError(
            f"fitness must be a function (metrics, cost, cfg) -> Tensor, "
            f"got {type(fitness).__name__}"
        )
    if getattr(fitness, "__wrapped_fitness__", False):
        return fitness

    @functools.wraps(fitness)
    def checked(metrics, cost, cfg):
        import torch

        out = fitness({k: v.clone() for k, v in metrics.items()}, cost.clone(), cfg)
        if isinstance(out, torch.Tensor) and out.numel() and out.is_floating_point():
            big = out.abs().max()
            if bool(torch.isfinite(big)) and float(big) > MAX_SCORE:
                raise ValueError(
                    f"the fitness function {score_fn_name(fitness)} returned a "
                    f"score of {float(big):.3g}, beyond the +-{MAX_SCORE:g} a run "
                    "can average (scale it down)"
                )
        return out

    checked.__module__ = getattr(fitness, "__module__", None) or type(fitness).__module__
    checked.__qualname__ = getattr(fitness, "__qualname__", None) or type(fitness).__qualname__
    checked.__wrapped_fitness__ = True
    return checked


def _wandb_reporters(project: str | None, run_dir: Path | None, render_every: int) -> list:
    """[a `WandbReporter` of `project` for `run_dir`], or [] for None; ImportError naming the
    extra, before anything runs."""
    from .reporting import WandbReporter

    return [] if project is None else [WandbReporter(project, run_dir, render_every=render_every)]


def file_reporters(
    run_dir: Path, checkpoint_every: int = 10, render_every: int = 50, figure_every: int = 50
) -> list:
    """The reporters that write a run directory, as `swarmcode-torch evolve` runs them:
    summary.json and teams.jsonl, metrics.csv, TensorBoard events (a replay image every
    `render_every` generations, 0: never; the composition figure every `figure_every`) and
    checkpoint.pt every `checkpoint_every` generations and at the end."""
    every = _intervals(
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
    best = ev.state.best
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


def _bounds(max_time, patience, stop=(), callback=None) -> session.Bounds | None:
    """The run's `session.Bounds` (None without max_time, patience, the early-stopping settings
    `stop` (`stopping.metric_stop`'s) and a callback); ValueError otherwise. The declared
    bounds (patience >= 1, stop_warmup >= 0) are checked with the other keywords'
    (`optspec.check_values`)."""
    from .stopping import CallbackStop, metric_stop

    metric = metric_stop(patience, *(tuple(stop) or (None,) * 4))
    stops = [metric] if metric is not None else []
    stops += [CallbackStop(callback)] if callback is not None else []
    if max_time is None and patience is None and not stops:
        return None
    return session.Bounds(max_time=max_time, patience=patience, stops=stops)


# ------------------------------------------------------------------ evolve, resume, load
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

    config: an `SwarmCoDeConfig` to start from (default: `SwarmCoDeConfig()`, the paper's budget
        experiment with the default preset; `preset="paper"` for the paper's algorithm with
        nothing beyond it), or the path of a settings file in the format of a run's config.toml
        (`swarmcode-torch evolve --config FILE`); `settings` replace its keys: `generations=20,
        population=30, seed=0, budget=4000.0, delta=0.5, ...` (any key of SwarmCoDeConfig / a
        run's config.toml).
    scenario: a built-in name, a path to a scenario TOML file, or a `Scenario` object.
    budget, objective, generations, population, swarm_size, trials, ticks, seed, device,
        compile, preset: the settings `swarmcode-torch evolve` has options for (UNSET: the
        config's), as any other key of `settings`.
    logdir: where the run directory is created (named as by the CLI,
        `SCENARIO[__bBUDGET][__OBJECTIVE]__SEED__TIME`); None: run in memory, write no file.
    checkpoint_every, render_every, figure_every: as `swarmcode-torch evolve`'s options
        (generations between checkpoints, TensorBoard replay images (0: never), composition
        figures).
    reporters: more reporters (objects with on_start(ev), on_generation(ev, result),
        on_end(ev)); callback: called with each generation's `GenerationResult`
        (`result.best_fitness`, `result.team`, ...; `records.scalars(result)` under the tags);
        returning True (or a non-empty string, the reason) stops the run after that generation,
        as `patience` does (`RunResult.stopped` "callback"; summary.json's "stop" has the
        reason); any other value (None, False) lets it go on.
    fitness: a function `fitness(metrics, cost, cfg) -> Tensor [E]` that scores each
        team-episode instead of the built-in fitness (`evaluation.team_scores`: F_raw times the
        budget penalty, / cost for roi): `metrics` maps names (`fitness.METRIC_KEYS`,
        "energy_used", ...) to [E] tensors, `cost` is the [E] team cost in $, `cfg` the run's
        `EvalConfig` (weights, budget, lam, objective). The marginal gate, the mean over trials
        and the EMA apply to its scores. The run records its name (config.toml's
        `fitness_function`, summary.json's "fitness"), and `resume` needs it again.
    threads: torch's CPU threads for this process (`sim.runtime.set_threads`; default:
        OMP_NUM_THREADS if set, else the cores less the load average, at least 1).
    wandb: a Weights & Biases project to log the run to as well (`reporting.WandbReporter`;
        needs the wandb extra, `pip install -e ".[wandb]"`; ImportError saying so before anything
        runs).
    from_run: "RUN" or "RUN@GENERATION": start a new run from that run's snapshot of GENERATION
        (or its latest checkpoint), as `swarmcode-torch evolve --from`: `settings` change the
        parent's config (its scenario, population, tag_length and bt_length stay), the new run
        records its parent (config.toml's [parent], summary.json's "parent"); `logdir` defaults
        to the parent's folder. A parent scored by a `fitness` function needs it again.
    snapshot_every: keep a copy of the checkpoint every N generations in the run directory's
        snapshots/ (0: none), to branch from with `from_run`.
    max_time, patience: stop cleanly (checkpoint written, `resume` continues it) after the
        generation that ends past `max_time` (seconds, or "90m", "2h", ...), or when the best
        team has not improved for `patience` generations; `RunResult.stopped` says which.
    stop_metric, stop_min_delta, stop_warmup, stop_mode: early stopping on a chosen metric
        (`stopping.MetricStop`; they need `patience`): stop when `stop_metric` (the run's best
        team's "best/fitness", the default, or a metrics.csv tag such as "team/fitness") has not
        improved by more than `stop_min_delta` for `patience` generations, counted from
        generation `stop_warmup` on; `stop_mode` "max" (the default) or "min".
    keep_checkpoints: also keep the last K checkpoints (RUN_DIR/checkpoints/generation-NNNNNN.pt)
        and the one of the run's best team (checkpoints/best.pt); 0 (the default): none.
    progress: print the run's progress on stdout, a compact line per generation (done count,
        time left, best fitness, species; redrawn in place on a terminal or in a notebook).
        None (the default): on a terminal or in a notebook, not when stdout is a file or a
        pipe; True: always; False: never.

    Raises ValueError (`ScenarioError` is one) for an invalid setting or scenario before any
    file is written. Ctrl-C in a run with a directory writes the checkpoint of the last finished
    generation (continue with `resume`) and re-raises KeyboardInterrupt.
    """
    o, settings = api_values(EVOLVE_OPTIONS, settings)
    check_values(o.options.values(), o)
    every = o.intervals(EVOLVE_OPTIONS)
    reporters = _check_hooks(callback, reporters)
    if wandb is not None and o.logdir is None:
        raise ValueError("wandb needs a run directory for its files: give a logdir")
    wandb_reporters = _wandb_reporters(wandb, None, every.render)
    fitness = _checked_fitness(fitness)
    bounds = _bounds(
        o.max_time,
        o.patience,
        (o.stop_metric, o.stop_min_delta, o.stop_warmup, o.stop_mode),
        callback,
    )
    shown = _progress(progress)
    set_threads(o.threads)
    reporters = [*([shown] if shown else []), *reporters, *wandb_reporters]
    scenario = settings.pop("scenario", None)
    if o.from_run is not None:
        return _branch(
            config,
            scenario,
            o,
            settings,
            fitness,
            reporters,
            callback,
            bounds,
            wandb_reporters,
            shown,
        )
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
    folder = None if o.logdir is None else _logdir(o.logdir)
    make_dir = None if folder is None else (lambda ev: new_run_dir(folder, name))
    history = _History()  # the callback is `bounds`': it may stop the run
    with ExitStack() as stack:
        start = session.start_new(
            stack, cfg, make_dir, scenario=scenario_obj, fitness=fitness, names=names or None
        )
        return _run_started(
            start, history, reporters, wandb_reporters, shown, bounds, every, o.keep_checkpoints
        )


#: evolve's signature shows every keyword it takes: those declared in
#: `run_options.RUN_OPTIONS` (`api=True`) before its own
declare_keywords(evolve, EVOLVE_OPTIONS)


def _run_started(
    start, history, reporters, wandb_reporters, shown, bounds, every, keep=0
) -> RunResult:
    """Run a new or branched run that `session` started (its directory locked by the caller's
    stack): the W&B reporters named after its directory, its file reporters (at `every`, the
    run's `Intervals`, keeping `keep` checkpoints; none for a run in memory), the progress line
    closed however the run ends. Its `RunResult`."""
    for r in wandb_reporters:  # named after the run directory, if there is one
        r.run_dir = start.run_dir
    reps = [] if start.run_dir is None else _file_reporters(start.run_dir, every, keep)
    with _closing(shown):
        session.run(start.ev, start.run_dir, [*reps, history, *reporters], bounds=bounds)
    return _result(start.ev, start.run_dir, history.rows, bounds)


def _branch(
    config,
    scenario,
    o: Values,
    settings,
    fitness,
    reporters,
    callback,
    bounds,
    wandb_reporters,
    shown,
) -> RunResult:
    """`evolve(from_run=...)`: a new run from a run's snapshot (`session.start_branch`); `o`:
    evolve's own keywords (`optspec.api_values`); `wandb_reporters`, `shown` as `_run_started`
    takes them."""
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
    folder = None if logdir is None else _logdir(logdir)
    make_dir = None if folder is None else (lambda ev: new_run_dir(folder, cfg, branch))
    history = _History()  # the callback is `bounds`'
    with ExitStack() as stack:
        start = session.start_branch(stack, branch, cfg, make_dir, fitness=fitness)
        every = o.intervals(EVOLVE_OPTIONS)
        return _run_started(
            start, history, reporters, wandb_reporters, shown, bounds, every, o.keep_checkpoints
        )


def start_evolution(
    cfg: SwarmCoDeConfig, scenario: Scenario | None = None, fitness: ScoreFn | None = None
) -> tuple[Evolution, bytes]:
    """The checks `swarmcode-torch evolve` makes before it creates anything (the config, the
    scenario, the memory the run needs), then the run's `Evolution` and the bytes of its
    scenario file (a run directory keeps them as scenario.toml). `scenario`: a Scenario object
    to run instead of `cfg.scenario`'s file; `fitness`: a user score function (`evolve`).
    ValueError (ScenarioError is one) otherwise."""
    fitness = _checked_fitness(fitness)
    checked, data = session.check_start(cfg, scenario)
    return session.build(cfg, checked, scenario, fitness), data


def _earlier_rows(run_dir: Path, before: int) -> list[dict]:
    from .files import METRICS_FILE
    from .reporting import read_metrics_csv

    path = Path(run_dir) / METRICS_FILE
    if not path.is_file():
        return []
    return [r for r in read_metrics_csv(path)[0] if r["generation"] < before]


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
    """Continue the run in `run_dir` from its checkpoint (as `swarmcode-torch evolve --resume`):
    to `generations` in all (default: the run's), on `device` (default: the run's);
    `fitness`: the run's own fitness function, for a run started with one (`evolve`). The
    result's history has every generation: those before the checkpoint from metrics.csv (when
    the run has one), then this part's. RunError (a ValueError) for a directory, config or
    checkpoint that cannot be used. `reporters`, `callback` (called with each generation's
    `GenerationResult`; it may stop the run), `threads`, `snapshot_every`, `max_time`,
    `patience`, the `stop_*` settings, `keep_checkpoints`, `wandb` and `progress`: as in
    `evolve` (`max_time` counts from this call); the keywords `run_options` declares are
    checked against their declared bounds, as in `evolve`."""
    d = _declared(
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
    every = d.intervals(EVOLVE_OPTIONS)
    reporters = _check_hooks(callback, reporters) + _wandb_reporters(
        wandb, Path(run_dir), every.render
    )
    fitness = _checked_fitness(fitness)
    bounds = _bounds(
        max_time, patience, (stop_metric, stop_min_delta, stop_warmup, stop_mode), callback
    )
    shown = _progress(progress)
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
            stack, run_dir, generations=generations, device=device, fitness=fitness
        )
        ev = start.ev
        earlier = _earlier_rows(run_dir, ev.state.generation)
        if ev.done:  # nothing to run: no file changes (as the CLI)
            return _result(ev, run_dir, earlier)
        history = _History()  # the callback is `bounds`'
        reps = _file_reporters(run_dir, every, keep_checkpoints)
        with _closing(shown):
            session.run(
                ev,
                run_dir,
                [*reps, history, *([shown] if shown else []), *reporters],
                bounds=bounds,
            )
    return _result(ev, run_dir, earlier + history.rows, bounds)


def load(run_dir: str | os.PathLike) -> RunResult:
    """The results of a run directory as they stand, without running anything: config,
    metrics.csv as the history (empty for a run written before metrics.csv existed), species
    composition and best team from the checkpoint. `evolution` is None."""
    run_dir = Path(run_dir)
    cfg, ck, scenario = load_run(run_dir)
    best = ck["best"]
    return RunResult(
        config=cfg,
        run_dir=run_dir,
        history=_earlier_rows(run_dir, math.inf),
        species=list(ck["history"]),
        best_team=dict(best) if best else None,
        scenario=scenario,
    )
