"""How a run starts, runs and ends: the one path that `swarmcode-torch evolve`, the Python API
(`api.evolve`, `api.resume`) and a sweep's runs (here or as Ray tasks) go through.

- `resolve_config` (the command line: a preset, its options, --set) and `make_config` (the API:
  a config and keys) give the run's config;
- `check_start` checks it before anything is made (its settings, its scenario, the memory it
  needs) and `build` makes the `Evolution`;
- `start_new` makes, locks and fills a new run directory (or none: a run in memory),
  `start_resume` locks and reopens one from its checkpoint;
- `file_reporters` are the reporters that write a run directory, and `run` is the generation
  loop: records, checkpoints, and an interrupt that keeps the last recorded generation.

The front ends add only what is theirs: the command line its options, messages and progress
(`terminal.execute`), the API its arguments and its `RunResult`.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable
from contextlib import ExitStack, nullcontext
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

from ..coevo.ask_tell import Evolution
from ..coevo.config import PRESETS, SwarmCoDeConfig, preset_config, with_overrides
from ..coevo.evaluation import ScoreFn
from ..sim.scenario import Scenario, read_scenario
from . import checkpoints, files, records
from .checkpoints import Branch, CheckpointReporter, evolution_from_checkpoint, load_run, resume
from .eta import parse_duration
from .files import HARDWARE_COPY, SCENARIO_COPY, RunError, atomic_write_bytes
from .locks import RunLock
from .reporter import Reporter
from .run_record import app_record, set_app_record
from .runconfig import (
    check_config,
    config_differences,
    hardware_bytes,
    read_parent,
    scenario_data,
    write_config,
    write_run_files,
)
from .settings import parse_settings
from .signals import deferred_signals, interrupt_of
from .summary import SummaryReporter

_CONFIG_KEYS = tuple(f.name for f in fields(SwarmCoDeConfig))


# ------------------------------------------------------------------ the config
def resolve_config(
    preset: str | None, settings: list[str] | None, names: dict[str, str] | None = None, **options
) -> SwarmCoDeConfig:
    """The config of the command line: the preset's (default: "default"), the options that are
    given (None: not given) on top, then the --set KEY=VALUE pairs (`settings.parse_settings`,
    its errors naming keys as `names` spells them), applied as given, none included."""
    return replace(
        with_overrides(preset_config("default" if preset is None else preset), **options),
        **parse_settings(settings or [], names),
    )


def make_config(config: SwarmCoDeConfig | None = None, **settings) -> SwarmCoDeConfig:
    """`config` (default `SwarmCoDeConfig()`) with `settings` (config keys) replaced; TypeError for
    an unknown key. A path scenario becomes a string. `preset="paper"` (`coevo.config.PRESETS`)
    sets the preset's algorithm settings first; the other settings go on top."""
    if config is not None and not isinstance(config, SwarmCoDeConfig):
        raise TypeError(f"config must be an SwarmCoDeConfig, got {type(config).__name__}")
    unknown = sorted(set(settings) - set(_CONFIG_KEYS))
    if unknown:
        raise TypeError(
            f"unknown setting(s) {', '.join(unknown)} (the keys of SwarmCoDeConfig: "
            f"{', '.join(_CONFIG_KEYS)})"
        )
    if isinstance(settings.get("scenario"), os.PathLike):
        settings["scenario"] = os.fspath(settings["scenario"])
    if "preset" in settings:  # the preset's settings first, then the others on top
        name = settings.pop("preset")
        if name not in PRESETS:
            raise ValueError(f"unknown preset {name!r} (presets: {', '.join(PRESETS)})")
        config = replace(
            config if config is not None else SwarmCoDeConfig(), **PRESETS[name], preset=name
        )
    return replace(config if config is not None else SwarmCoDeConfig(), **settings)


# ------------------------------------------------------------------ starting
def check_start(
    cfg: SwarmCoDeConfig, scenario: Scenario | None = None, names: dict[str, str] | None = None
) -> tuple[Scenario, bytes]:
    """The checks made before anything is created: the config's settings, its scenario (read
    from `cfg.scenario`'s file, or `scenario`, a Scenario object, checked to survive a round
    trip through TOML), then the memory the run needs and the settings' upper bounds
    (`runconfig.check_config`). ValueError (ScenarioError is one), one line, naming settings as
    `names` spells them. The scenario and the bytes a run directory keeps as scenario.toml."""
    if scenario is None:
        scen, data = read_scenario(cfg.scenario)
    else:
        scen, data = scenario, scenario_data(scenario)
    check_config(cfg, scen, names)
    return scen, data


def build(
    cfg: SwarmCoDeConfig,
    checked: Scenario | None = None,
    scenario: Scenario | None = None,
    fitness: ScoreFn | None = None,
) -> Evolution:
    """The run's `Evolution`: of `cfg`'s scenario file, or of `scenario`, a Scenario object
    (named by its name: nothing reloads it during a run; its run directory keeps its TOML, which
    resume, replay and inspect read). `checked`: the scenario `check_start` read, which the run's
    must still be (ValueError otherwise)."""
    ev = (
        Evolution(cfg, fitness=fitness, checked=True)
        if scenario is None
        else Evolution(
            replace(cfg, scenario=scenario.name), fitness=fitness, scenario=scenario, checked=True
        )
    )
    if checked is not None and ev.ctx.scenario != checked:
        raise ValueError(f"{cfg.scenario} changed while the run was starting; start it again")
    return ev


@dataclass
class Start:
    """A started run: its Evolution (None: a resume with nothing to do), its run directory (None:
    in memory) and the generation its checkpoint file holds (None: none yet)."""

    ev: Evolution | None
    run_dir: Path | None
    saved: int | None = None


def start_new(
    stack: ExitStack,
    cfg: SwarmCoDeConfig,
    make_dir: Callable[[Evolution], Path] | None,
    *,
    scenario: Scenario | None = None,
    fitness: ScoreFn | None = None,
    names: dict[str, str] | None = None,
    data: bytes | None = None,
    before_build: Callable[[], None] | None = None,
    attach: Callable[[Evolution], None] | None = None,
    on_dir: Callable[[Path], None] | None = None,
) -> Start:
    """A new run: its config checked (`check_start`; not when `data`, its scenario's bytes, is
    given: the caller checked it), `before_build()`, its `Evolution` built, `attach(ev)`
    (evaluation shards) before any file is written, then its directory made (`make_dir(ev)`;
    None: a run in memory, no file), locked until `stack` closes, `on_dir(run_dir)`, and
    config.toml, scenario.toml and hardware.toml written."""
    checked = None
    if data is None:
        checked, data = check_start(cfg, scenario, names)
    if before_build is not None:
        before_build()
    ev = build(cfg, checked, scenario, fitness)
    run_dir = _open_dir(stack, ev, make_dir, attach, on_dir)
    if run_dir is None:
        return Start(ev, None)
    write_run_files(run_dir, ev.cfg, data, ev.ctx.scenario.hardware)
    return Start(ev, run_dir)


def start_resume(
    stack: ExitStack,
    run_dir: Path,
    *,
    generations: int | None = None,
    device: str | None = None,
    fitness: ScoreFn | None = None,
    stop_if_done: bool = False,
    on_locked: Callable[[Path], None] | None = None,
    on_loaded: Callable[[int], None] | None = None,
    attach: Callable[[Evolution], None] | None = None,
) -> Start:
    """The run in `run_dir` reopened: locked until `stack` closes (`on_locked(run_dir)`), its
    config, checkpoint and scenario loaded and checked (`checkpoints.load_run`; `on_loaded(the
    checkpoint's generation)`), continued to `generations` on `device` (`checkpoints.resume`),
    `attach(ev)`, and its config.toml rewritten. A run with nothing left to do changes no file:
    with `stop_if_done` its Evolution is not even built (`Start.ev` None)."""
    stack.enter_context(RunLock(run_dir))
    if on_locked is not None:
        on_locked(run_dir)
    loaded = load_run(run_dir)
    saved = loaded[1]["generation"]
    if on_loaded is not None:
        on_loaded(saved)
    if stop_if_done and (loaded[0].generations if generations is None else generations) <= saved:
        return Start(None, run_dir, saved)
    ev = resume(run_dir, generations=generations, device=device, loaded=loaded, fitness=fitness)
    if ev.done:
        return Start(ev, run_dir, saved)
    if attach is not None:
        attach(ev)
    write_config(run_dir, ev.cfg, read_parent(run_dir))  # a branched run stays one
    return Start(ev, run_dir, ev.state.generation)


#: The settings a branch keeps from its parent: the snapshot's tensors are of its population,
#: tag_length and bt_length, and its species, fitness and best team were found on its scenario
#: (which the branch runs from the parent's own scenario.toml and hardware.toml copies).
BRANCH_FIXED = ("scenario", "population", "tag_length", "bt_length")


def check_branch(branch: Branch, cfg: SwarmCoDeConfig, names: dict[str, str] | None = None) -> None:
    """ValueError, one line, for a branch config `cfg` that changes a setting of `BRANCH_FIXED`
    or has no generation left to run after the snapshot's."""
    names = names or {}
    diff = set(config_differences(branch.config, cfg, branch.scenario, ignore=()))
    fixed = [k for k in BRANCH_FIXED if k in diff]
    if fixed:
        k = fixed[0]
        raise ValueError(
            f"{names.get(k, k)} cannot change when branching from {branch.run_dir} "
            f"(it is {getattr(branch.config, k)!r}; the snapshot's population, "
            f"species and fitness are of it): start a new run instead"
        )
    if cfg.generations <= branch.generation:
        raise ValueError(
            f"{names.get('generations', 'generations')} must be more than the "
            f"snapshot's {branch.generation} generations to branch, got "
            f"{cfg.generations}"
        )


def _open_dir(
    stack: ExitStack,
    ev: Evolution,
    make_dir: Callable[[Evolution], Path] | None,
    attach: Callable[[Evolution], None] | None,
    on_dir: Callable[[Path], None] | None,
) -> Path | None:
    """A new run's steps once its `Evolution` is built: `attach(ev)` (evaluation shards) before
    any file is written, then its directory made (`make_dir(ev)`; None: a run in memory, no
    directory, None returned), locked until `stack` closes, and `on_dir(run_dir)`."""
    if attach is not None:
        attach(ev)
    if make_dir is None:
        return None
    run_dir = make_dir(ev)
    stack.enter_context(RunLock(run_dir))
    if on_dir is not None:
        on_dir(run_dir)
    return run_dir


def start_branch(
    stack: ExitStack,
    branch: Branch,
    cfg: SwarmCoDeConfig,
    make_dir: Callable[[Evolution], Path] | None,
    *,
    fitness: ScoreFn | None = None,
    names: dict[str, str] | None = None,
    before_build: Callable[[], None] | None = None,
    attach: Callable[[Evolution], None] | None = None,
    on_dir: Callable[[Path], None] | None = None,
) -> Start:
    """A new run that starts from `branch` (`checkpoints.load_branch`: a run's snapshot) with the
    config `cfg` (the parent's with changed settings; `check_branch`, then `check_config`): its
    first generation continues the snapshot's state, with `cfg`'s settings. A changed seed
    restarts the random generator from it (the same seed continues the parent's stream). Its
    directory (`make_dir(ev)`; None: in memory) gets config.toml with a [parent] table
    (`Branch.parent`) and the parent's own scenario.toml and hardware.toml."""
    check_branch(branch, cfg, names)
    check_config(cfg, branch.scenario, names)
    if before_build is not None:
        before_build()
    try:
        ev = evolution_from_checkpoint(branch.checkpoint, cfg, fitness, branch.scenario)
    except ValueError as e:
        raise RunError(f"{branch.path} cannot start the branch: {e}") from None
    if cfg.seed != branch.config.seed:
        from ..coevo.evolve import new_generator

        ev.state.rng_state = new_generator(ev.ctx).get_state()
    run_dir = _open_dir(stack, ev, make_dir, attach, on_dir)
    if run_dir is None:
        return Start(ev, None)
    write_config(run_dir, ev.cfg, branch.parent)
    atomic_write_bytes(
        run_dir / SCENARIO_COPY,
        branch.scenario_bytes
        if branch.scenario_bytes is not None
        else scenario_data(branch.scenario),
    )
    atomic_write_bytes(
        run_dir / HARDWARE_COPY,
        branch.hardware_bytes
        if branch.hardware_bytes is not None
        else hardware_bytes(branch.scenario.hardware),
    )
    return Start(ev, run_dir)


# ------------------------------------------------------------------ running
def file_reporters(
    run_dir: Path,
    checkpoint_every: int = 10,
    render_every: int = 50,
    figure_every: int = 50,
    saved: int | None = None,
    snapshot_every: int = 0,
    keep_checkpoints: int = 0,
) -> list:
    """The reporters that write a run directory: summary.json and teams.jsonl, metrics.csv,
    TensorBoard events (a replay image every `render_every` generations, 0: never; the
    composition figure every `figure_every`) and, last, checkpoint.pt every `checkpoint_every`
    generations and at the end (`saved`: the generation the file holds when the run starts),
    and a snapshot of it every `snapshot_every` generations (0: none); with `keep_checkpoints`
    K > 0, the last K checkpoints and the best one too (`keep.KeepingCheckpoints`)."""
    from .keep import checkpoint_reporter
    from .reporting import CsvReporter, TensorBoardReporter

    checkpoint = checkpoint_reporter(run_dir, checkpoint_every, snapshot_every, keep_checkpoints)
    checkpoint.saved = saved
    return [
        SummaryReporter(run_dir),
        CsvReporter(run_dir),
        TensorBoardReporter(run_dir, figure_every=figure_every, render_every=render_every),
        checkpoint,
    ]


def clock() -> float:
    """The clock --max-time reads (seconds, monotonic); tests replace it."""
    return time.monotonic()


@dataclass
class Bounds:
    """Where a run stops before its last generation, both optional: `max_time` seconds of the
    run loop (`clock`; checked after each generation, so the generation that crosses it ends
    first) and `patience`, generations without a better best team (the run's best team, found
    at its "generation", not improved in the last `patience` generations). After the run,
    `reason` says which stopped it ("max_time", "patience"; None: neither) and `elapsed` how
    long the loop ran."""

    max_time: float | None = None
    patience: int | None = None
    reason: str | None = None
    elapsed: float = 0.0
    stops: list = field(default_factory=list)  # more (`stopping`); `stopper`: the one that stopped
    stopper: object = None

    def __post_init__(self) -> None:
        if self.patience is not None and (
            not isinstance(self.patience, int)
            or isinstance(self.patience, bool)
            or self.patience < 1
        ):
            raise ValueError(f"patience must be an integer >= 1, got {self.patience!r:.40}")
        if self.max_time is not None:
            self.max_time = parse_duration(self.max_time)

    def reached(self, ev: Evolution, elapsed: float, result=None) -> str | None:
        """The bound `ev`'s state, `elapsed` seconds into the run, has reached (None: none; a
        run at its last generation has reached none: it ends); every stop sees `result`."""
        said = [(s, s.check(ev, result)) for s in self.stops] if result is not None else []
        if ev.done:
            return None
        for s, reason in said:
            if reason is not None:
                self.stopper = s
                return reason
        on_metric = any(s.reason == "patience" for s in self.stops)  # --patience --stop-metric
        best = app_record(ev).best
        if self.patience is not None and best is not None and not on_metric:
            last = ev.state.generation - 1
            if last - int(best["generation"]) >= self.patience:
                return "patience"
        if self.max_time is not None and elapsed >= self.max_time:
            return "max_time"
        return None

    def record(self, ev: Evolution) -> dict:
        """summary.json's "stop" of a run this stopped."""
        out: dict = {"reason": self.reason, "generation": ev.state.generation}
        if self.stopper is not None:
            out.update(self.stopper.record())  # type: ignore[attr-defined]
        elif self.reason == "patience":
            out.update(
                patience=self.patience, best_generation=int(app_record(ev).best["generation"])
            )
        else:
            out.update(max_time_seconds=self.max_time, elapsed_seconds=round(self.elapsed, 3))
        return out


def _stop(ev: Evolution, bounds: Bounds, reason: str, saver, reporters: list) -> None:
    """A bound reached: the reason kept, the checkpoint written, the reporters told
    (`on_stop`, with summary.json's "stop" record)."""
    bounds.reason = reason
    if saver is not None:
        saver.save_state(ev)
    for r in reporters:
        if callable(getattr(r, "on_stop", None)):
            r.on_stop(ev, bounds.record(ev))


def run(
    ev: Evolution,
    run_dir: Path | None,
    reporters: Iterable[Reporter],
    on_interrupt: Callable[[Path], None] | None = None,
    bounds: Bounds | None = None,
) -> Evolution:
    """Run generations until the configured total.

    Each generation is one step that Ctrl-C or SIGTERM cannot split (`deferred_signals`): the
    reporters up to the last `CheckpointReporter` in `reporters` (the run's records: summary,
    teams.jsonl, metrics.csv, TensorBoard) write it, then its checkpoint is written when one is
    due; the reporters after it (a progress callback, a user's) run outside that step. On an
    interrupt (anywhere: while a generation computes, while the run starts, in the end-of-run
    work) the state whose records are all written is kept (a generation computed but not yet
    recorded is dropped: a resume computes it again, identically), its checkpoint written if the
    file does not hold it yet, and KeyboardInterrupt re-raised; the `CheckpointReporter`'s
    `saved` then names the generation the file holds. `run_dir` None: a run in memory, which
    writes nothing, holds no signal and is interrupted where it stands.

    `bounds` (`Bounds`): a run that reaches one stops cleanly after the generation that reached
    it, as it ends: its checkpoint written (resume continues it as if it had not stopped), the
    "stop" of summary.json recorded (reporters with an `on_stop(ev, record)`), every reporter's
    on_end called; `bounds.reason` says why."""
    reporters = list(reporters)
    on_disk = run_dir is not None
    hold = deferred_signals if on_disk else nullcontext
    marks = [i for i, r in enumerate(reporters) if isinstance(r, CheckpointReporter)]
    saver = reporters[marks[-1]] if marks else None
    cut = marks[-1] + 1 if marks else len(reporters)
    step_reporters, after = reporters[:cut], reporters[cut:]
    # the last state whose records are all written, and the application's record of it
    recorded = ev.state, replace(app_record(ev))
    t0 = clock()
    try:
        with hold():
            for r in reporters:
                r.on_start(ev)
        for s in bounds.stops if bounds is not None else []:
            s.start(ev, run_dir)  # a resumed run's earlier values
        while not ev.done:
            result = records.step(ev)
            if on_disk:
                files.interrupt_point("generation")
            with hold():
                for r in step_reporters:
                    r.on_generation(ev, result)
                recorded = ev.state, replace(app_record(ev))
                reason = None
                if bounds is not None:
                    bounds.elapsed = clock() - t0
                    reason = bounds.reached(ev, bounds.elapsed, result)
                if reason is not None:
                    _stop(ev, bounds, reason, saver, reporters)
            for r in after:
                r.on_generation(ev, result)
            if reason is not None:
                break
        for r in reporters:
            r.on_end(ev)
    except BaseException as e:
        interrupt = interrupt_of(e)
        if interrupt is None or not on_disk:
            raise
        with deferred_signals(deliver=False):  # a second Ctrl-C cannot split this checkpoint
            ev.state = recorded[0]
            set_app_record(ev, recorded[1])
            if saver is not None:
                saver.save_state(ev)
                path = Path(run_dir) / files.CHECKPOINT_FILE
            else:
                path = checkpoints.save_checkpoint(run_dir, ev)
        if on_interrupt:
            on_interrupt(path)
        raise interrupt from None
    return ev
