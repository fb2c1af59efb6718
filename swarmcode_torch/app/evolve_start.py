"""What `swarmcode-torch evolve` does before its run: its options checked and turned into the
run's config (a preset or --config FILE, --from RUN[@GENERATION], the options, --set), the
bounds (--max-time, --patience, --stop-*) and --wandb, and the new, resumed or branched run started
through `session` with its run directory locked."""

from __future__ import annotations

import sys
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path

from rich.markup import escape

from ..coevo.config import with_overrides
from ..sim.scenario import ScenarioError
from . import session
from .optspec import Values, check_values
from .run_record import app_record
from .settings import option_names, parse_settings
from .signals import TERMINATED, terminate_as_interrupt
from .terminal import (
    Where,
    attach_shards,
    check_path,
    console,
    eval_shards_option,
    execute,
    fail,
    os_fail,
    print_shard_traffic,
    print_team,
    set_threads_option,
    stopped,
)


def wandb_option(on: bool, project: str) -> str | None:
    """The W&B project of `evolve --wandb` (None: off); a one-line error without wandb."""
    if not on:
        return None
    from .reporting import check_wandb_settings, require_wandb

    try:
        require_wandb()
        check_wandb_settings(project)
    except (ImportError, ValueError) as e:
        fail(str(e))
    return project


def bounds_option(o: Values):
    """The run's `session.Bounds` of evolve's options (None without --max-time, --patience and
    the --stop-* options, `stopping.metric_stop`'s); one-line errors. The declared bounds
    (--patience >= 1, --stop-warmup >= 0) are checked with the other options'
    (`optspec.check_values`)."""
    from .stopping import metric_stop

    stop = (o.stop_metric, o.stop_min_delta, o.stop_warmup, o.stop_mode)
    try:
        metric = metric_stop(o.patience, *stop, dash=True)
    except ValueError as e:
        fail(str(e))
    if o.max_time is None and o.patience is None:
        return None
    try:
        return session.Bounds(
            max_time=o.max_time, patience=o.patience, stops=[metric] if metric else []
        )
    except ValueError as e:
        fail(f"--{e}".replace("--max_time", "--max-time"))


def bound_line(bounds, ev, run_dir: Path) -> str:
    """What a run stopped by --max-time, --patience or a --stop-metric prints."""
    from .stop_lines import generations_done  # a count, and the numbers from 0

    g = ev.state.generation
    if bounds.stopper is not None:
        why = bounds.stopper.why()
    elif bounds.reason == "patience":
        why = (
            f"the best team (generation {app_record(ev).best['generation']}) has not improved for "
            f"{bounds.patience} generations (--patience {bounds.patience})"
        )
    else:
        why = f"--max-time reached ({bounds.elapsed:.1f}s of {bounds.max_time:g}s)"
    return (
        f"Stopped after {generations_done(g)}: {why}; its checkpoint is in "
        f"{run_dir}; continue with: swarmcode-torch evolve --resume {run_dir}"
    )


def _spell(o) -> str:
    return o.spelling


def new_config(o: Values):
    """(the config of a new run of evolve's options `o`, its `checkpoints.Branch` or None, how
    its checks name each key): `config_from`."""
    return config_from(o.config, o.from_run, o.preset, o.settings, o.config_keys(skip=("preset",)))


def config_from(config_file: Path | None, from_run: str | None, preset, settings, given: dict):
    """(the config of a new run: --config FILE or the preset, or the --from run's, with
    --preset, the options' config keys `given` and --set on top; the `checkpoints.Branch` of
    --from, or None; how the errors of its checks name each key: --population, --set delta,
    FILE: delta). evolve and sweep (its --config) make their configs here."""
    from .checkpoints import load_branch, parse_run_ref
    from .runconfig import read_config_file_keys

    names = option_names()
    branch = None
    if from_run is not None:
        if config_file is not None:
            fail(
                "--config and --from cannot be used together: a branch starts from its "
                "parent's config (give the changes as options and --set)"
            )
        run, generation = parse_run_ref(from_run)
        check_path(str(run), "--from")
        branch = load_branch(run, generation)
        if branch.config.fitness_function is not None:
            fail(
                f"{run} was scored by a custom fitness function "
                f"({branch.config.fitness_function}): branch it from Python, "
                "swarmcode_torch.evolve(from_run=..., fitness=fn)"
            )
        base = branch.config
    elif config_file is not None:
        base, keys = read_config_file_keys(config_file)
        if base.fitness_function is not None:
            fail(
                f"{config_file}: fitness_function: a fitness function is given from Python "
                "(swarmcode_torch.evolve(config=FILE, fitness=fn))"
            )
        # a key the file sets is the file's to answer for, unless an option or --set replaces it
        names.update({k: f"{config_file}: {k}" for k in keys})
    else:
        return session.resolve_config(preset, settings, names, **given), None, names
    if preset is not None:
        base = session.make_config(base, preset=preset)
    plain = option_names()
    pairs = parse_settings(settings or [], plain)
    names.update({k: plain[k] for k in (*given, *pairs)})
    return replace(with_overrides(base, **given), **pairs), branch, names


def print_resolved_config(o: Values) -> None:
    """--print-config: the resolved config of a new run (checked), as TOML, on stdout."""
    from .files import RunError
    from .runconfig import config_to_toml

    if o.resume is not None:
        fail("--print-config is for a new run; a resumed run's config is its config.toml")
    try:
        cfg, branch, names = new_config(o)
        if branch is None:
            session.check_start(cfg, names=names)
        else:
            session.check_branch(branch, cfg, names)
            cfg.validate()
    except (ScenarioError, RunError, ValueError) as e:
        fail(str(e))
    except OSError as e:
        os_fail(e, "cannot read the config")
    header = (
        "# swarmcode-torch settings (start a run with them: swarmcode-torch evolve --config FILE)"
    )
    sys.stdout.write(config_to_toml(cfg, parent=branch.parent if branch else None, header=header))
    sys.stdout.flush()


#: The options a resumed run may change (its config is its own).
RESUME_CHANGES = ("generations", "device")


def _resume_conflicts(o: Values) -> list[str]:
    """The options given with --resume that would change the run's config."""
    taken = ("settings", "config", "from_run")
    return [
        opt.spelling
        for name, opt in o.options.items()
        if (opt.setting is not None and name not in RESUME_CHANGES or name in taken)
        and o[name] not in (None, [])
    ]


def _start_resume(stack: ExitStack, o: Values, where: Where, attach):
    """--resume: the run reopened (`start_evolve`)."""
    resume, generations = o.resume, o.generations
    if generations is not None and generations < 1:
        fail(f"--generations must be >= 1 (the total to extend the run to), got {generations}")
    extra = _resume_conflicts(o)
    if extra:
        fail(
            f"--resume uses the run's saved config; only --generations and --device may "
            f"change (got {', '.join(extra)})"
        )
    if o.logdir is not None:
        fail(
            f"--logdir cannot be used with --resume: the run continues in its own "
            f"directory ({resume})"
        )
    if not resume.is_dir():
        fail(f"--resume {resume} is not a run directory (no such directory)")

    def locked(run_dir: Path) -> None:
        where.run_dir, where.resuming = run_dir, True

    def loaded(saved: int) -> None:
        where.saved = saved

    start = session.start_resume(
        stack,
        resume,
        generations=generations,
        device=o.device,
        stop_if_done=True,
        on_locked=locked,
        on_loaded=loaded,
        attach=attach,
    )
    if start.ev is None:
        console.print(
            f"{resume} already has {start.saved} generations"
            f"{'' if generations is None else f' (asked for {generations})'}; "
            "nothing to do, no file changed",
            markup=False,
            highlight=False,
            soft_wrap=True,
        )
        return None, resume, None
    ev = start.ev
    console.print(
        f"Resuming [bold]{escape(str(resume))}[/] at generation "
        f"{ev.state.generation} of {ev.cfg.generations}",
        soft_wrap=True,
    )
    return ev, resume, start.saved


def start_evolve(stack: ExitStack, o: Values, *, where: Where, attach=None):
    """Start the run of evolve's options `o` (paths already checked): (Evolution, run
    directory, generation of its checkpoint), or (None, ...) when a resume has nothing to do.
    The run directory's lock is held until `stack` closes. `attach(ev)`, if given, is called
    once the Evolution exists and before any file is written (evaluation shards)."""
    from .files import RunError, new_run_dir

    try:
        if o.resume is not None:
            return _start_resume(stack, o, where, attach)
        cfg, branch, names = new_config(o)
        logdir = o.logdir
        if logdir is None:  # a branch goes beside its parent
            logdir = branch.run_dir.parent if branch is not None else Path("runs")

        def check_logdir() -> None:  # after the config's checks, before the Evolution
            if logdir.exists() and not logdir.is_dir():
                fail(f"--logdir {logdir} is not a directory")

        def make_dir(ev) -> Path:
            try:
                return new_run_dir(logdir, cfg, branch)
            except OSError as e:
                os_fail(e, f"--logdir {logdir}: cannot make a run directory")

        on_dir = lambda run_dir: setattr(where, "run_dir", run_dir)  # noqa: E731
        steps = dict(names=names, before_build=check_logdir, attach=attach, on_dir=on_dir)
        if branch is not None:
            start = session.start_branch(stack, branch, cfg, make_dir, **steps)
            console.print(
                f"Branching from {escape(str(branch.path))} (generation {branch.generation})",
                highlight=False,
            )
        else:
            start = session.start_new(stack, cfg, make_dir, **steps)
        ev, run_dir = start.ev, start.run_dir
        assert ev is not None  # a new run's start has its Evolution
        console.print(
            f"Run directory: [bold]{escape(str(run_dir))}[/]  (device {ev.ctx.device}, "
            f"scenario {escape(ev.ctx.scenario.name)}, population {cfg.population}, "
            f"swarm {ev.ctx.eval_cfg.swarm_size}, tick {ev.ctx.tick_mode})",
            soft_wrap=True,
        )
        return ev, run_dir, None
    except (ScenarioError, RunError, ValueError) as e:
        fail(str(e))
    except OSError as e:
        os_fail(e, "cannot start the run")


def checked_options(o: Values) -> Values:
    """evolve's options with their paths checked (`terminal.check_path`) and every bound
    (`optspec.check_values`, the messages naming the options as the command line spells them);
    a one-line error otherwise."""
    o = o.replace(
        logdir=check_path(o.logdir, "--logdir"),
        resume=check_path(o.resume, "--resume"),
        config=check_path(o.config, "--config"),
    )
    try:
        check_values(o.options.values(), o, _spell)
    except (TypeError, ValueError) as e:
        fail(str(e))
    return o


def evolve_command(o: Values) -> None:
    """The `evolve` command's work, with its options as `cli.evolve` parsed them
    (`run_options.EVOLVE_OPTIONS`): the run started (new, resumed or branched), run with
    progress, and its end printed."""
    o = checked_options(o)
    wandb_project = wandb_option(o.wandb, o.wandb_project)
    TERMINATED.clear()  # this command's SIGTERM, not an earlier one's
    bounds = bounds_option(o)
    if o.print_config:
        print_resolved_config(o)
        return
    set_threads_option(o.threads)
    shards = eval_shards_option(o.eval_workers, o.cpus_per_eval_worker, o.ray_address)
    every = o.intervals()
    where = Where()
    with terminate_as_interrupt() as terminated:
        try:
            with ExitStack() as stack:
                attach = None if shards is None else (lambda ev: attach_shards(stack, ev, *shards))
                ev, run_dir, saved = start_evolve(stack, o, where=where, attach=attach)
                if ev is None:
                    return
                execute(
                    ev,
                    run_dir,
                    every.checkpoint,
                    every.log,
                    every.render,
                    saved=saved,
                    figure_every=every.figure,
                    where=where,
                    snapshot_every=every.snapshot,
                    bounds=bounds,
                    wandb_project=wandb_project,
                    keep_checkpoints=o.keep_checkpoints,
                )
                if shards is not None:
                    print_shard_traffic(ev.ctx.evaluator)
            print_end(bounds, ev, run_dir)
        except KeyboardInterrupt:
            stopped(where, bool(terminated))


def print_end(bounds, ev, run_dir: Path) -> None:
    """What a finished (or bounded) run prints: why it ended, its team, what to run next."""
    if bounds is not None and bounds.reason is not None:
        console.print(
            bound_line(bounds, ev, run_dir), markup=False, highlight=False, soft_wrap=True
        )
    else:
        console.print(
            f"Done: {ev.state.generation} generations in {escape(str(run_dir))}", soft_wrap=True
        )
    print_team(run_dir)
    # commands and paths are never wrapped (soft_wrap): each stays one line to copy
    console.print(
        f"Inspect: swarmcode-torch inspect {run_dir}", markup=False, highlight=False, soft_wrap=True
    )
    console.print(
        f"Watch: tensorboard --logdir {run_dir.parent}",
        markup=False,
        highlight=False,
        soft_wrap=True,
    )
