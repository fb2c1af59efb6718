"""What `swarmcode-torch evolve` does before its run: its options checked and turned into the
run's config (a preset or --config FILE, --from RUN[@GENERATION], the options, --set), the
bounds (--max-time, --patience) and --wandb, and the new, resumed or branched run started
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
from .options import objective_value
from .settings import parse_settings
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


def bounds_option(max_time: str | None, patience: int | None, snapshot_every: int, stop=None):
    """The run's `session.Bounds` (None without --max-time, --patience and `stop`: the
    --stop-* options, `stopping.metric_stop`'s arguments); one-line errors."""
    from .stopping import metric_stop

    if snapshot_every < 0:
        fail(f"--snapshot-every must be >= 0 (0: no snapshots), got {snapshot_every}")
    try:
        metric = metric_stop(patience, *(stop or (None,) * 4), dash=True)
    except ValueError as e:
        fail(str(e))
    if max_time is None and patience is None:
        return None
    if patience is not None and patience < 1:
        fail(f"--patience must be >= 1 (generations without a better best team), got {patience}")
    try:
        return session.Bounds(
            max_time=max_time, patience=patience, stops=[metric] if metric else []
        )
    except ValueError as e:
        fail(f"--{e}".replace("--max_time", "--max-time"))


def bound_line(bounds, ev, run_dir: Path) -> str:
    """What a run stopped by --max-time or --patience prints."""
    g = ev.state.generation
    if bounds.stopper is not None:
        why = bounds.stopper.why()
    elif bounds.reason == "patience":
        why = (
            f"the best team (generation {ev.state.best['generation']}) has not improved for "
            f"{bounds.patience} generations (--patience {bounds.patience})"
        )
    else:
        why = f"--max-time reached ({bounds.elapsed:.1f}s of {bounds.max_time:g}s)"
    from .stop_lines import generations_done  # a count, and the numbers from 0

    return (
        f"Stopped after {generations_done(g)}: {why}; its checkpoint is in "
        f"{run_dir}; continue with: swarmcode-torch evolve --resume {run_dir}"
    )


def new_config(config_file: Path | None, from_run: str | None, preset, settings, **given):
    """(the config of a new run: --config FILE or the preset, or the --from run's, with
    --preset, the options and --set on top; the `checkpoints.Branch` of --from, or None)."""
    from .checkpoints import load_branch, parse_run_ref
    from .runconfig import read_config_file
    from .settings import option_names

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
        base = read_config_file(config_file)
        if base.fitness_function is not None:
            fail(
                f"{config_file}: fitness_function: a fitness function is given from Python "
                "(swarmcode_torch.evolve(config=FILE, fitness=fn))"
            )
    else:
        return session.resolve_config(preset, settings, **given), None
    if preset is not None:
        base = session.make_config(base, preset=preset)
    names = option_names()
    return replace(with_overrides(base, **given), **parse_settings(settings or [], names)), branch


def print_resolved_config(config_file, from_run, resume, preset, settings, **given) -> None:
    """--print-config: the resolved config of a new run (checked), as TOML, on stdout."""
    from .files import RunError
    from .runconfig import config_to_toml
    from .settings import option_names

    if resume is not None:
        fail("--print-config is for a new run; a resumed run's config is its config.toml")
    try:
        cfg, branch = new_config(config_file, from_run, preset, settings, **given)
        if branch is None:
            session.check_start(cfg, names=option_names())
        else:
            session.check_branch(branch, cfg, option_names())
            cfg.validate(option_names())
    except (ScenarioError, RunError, ValueError) as e:
        fail(str(e))
    except OSError as e:
        os_fail(e, "cannot read the config")
    header = (
        "# swarmcode-torch settings (start a run with them: swarmcode-torch evolve --config FILE)"
    )
    sys.stdout.write(config_to_toml(cfg, parent=branch.parent if branch else None, header=header))
    sys.stdout.flush()


def start_evolve(
    stack: ExitStack,
    *,
    scenario,
    budget,
    objective,
    generations,
    population,
    swarm_size,
    trials,
    ticks,
    seed,
    device,
    compile,
    logdir,
    checkpoint_every,
    log_every,
    render_every,
    resume,
    settings,
    attach=None,
    figure_every=50,
    where: Where,
    preset=None,
    config_file=None,
    from_run=None,
):
    """Check the options, then make (or lock and reopen) the run directory: (Evolution, run
    directory, generation of its checkpoint), or (None, ...) when a resume has nothing to do.
    The run directory's lock is held until `stack` closes. `attach(ev)`, if given, is called
    once the Evolution exists and before any file is written (evaluation shards)."""
    from .files import RunError, new_run_dir
    from .settings import option_names

    if checkpoint_every < 1 or log_every < 1 or figure_every < 1 or render_every < 0:
        fail("--checkpoint-every, --log-every and --figure-every must be >= 1, --render-every >= 0")
    given = dict(
        scenario=scenario,
        budget=budget,
        objective=objective,
        population=population,
        swarm_size=swarm_size,
        trials=trials,
        ticks=ticks,
        seed=seed,
        compile=compile,
    )
    try:
        if resume is not None:
            if generations is not None and generations < 1:
                fail(
                    f"--generations must be >= 1 (the total to extend the run to), got "
                    f"{generations}"
                )
            extra = [k.replace("_", "-") for k, v in given.items() if v is not None]
            extra += ["set"] if settings else []
            extra += ["preset"] if preset is not None else []
            extra += ["config"] if config_file is not None else []
            extra += ["from"] if from_run is not None else []
            if extra:
                fail(
                    f"--resume uses the run's saved config; only --generations and --device may "
                    f"change (got --{', --'.join(extra)})"
                )
            if logdir is not None:
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
                device=device,
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
        cfg, branch = new_config(
            config_file, from_run, preset, settings, generations=generations, device=device, **given
        )
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
        if branch is not None:
            start = session.start_branch(
                stack,
                branch,
                cfg,
                make_dir,
                names=option_names(),
                before_build=check_logdir,
                attach=attach,
                on_dir=on_dir,
            )
            console.print(
                f"Branching from {escape(str(branch.path))} (generation {branch.generation})",
                highlight=False,
            )
        else:
            start = session.start_new(
                stack,
                cfg,
                make_dir,
                names=option_names(),
                before_build=check_logdir,
                attach=attach,
                on_dir=on_dir,
            )
        ev, run_dir = start.ev, start.run_dir
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


def evolve_command(
    *,
    scenario,
    budget,
    objective,
    generations,
    population,
    swarm_size,
    trials,
    ticks,
    seed,
    device,
    compile,
    logdir,
    checkpoint_every,
    log_every,
    render_every,
    figure_every,
    resume,
    preset,
    settings,
    eval_workers,
    cpus_per_eval_worker,
    ray_address,
    threads,
    config,
    print_config,
    from_run,
    snapshot_every,
    max_time,
    patience,
    wandb,
    wandb_project,
    stop_metric=None,
    stop_min_delta=None,
    stop_warmup=None,
    stop_mode=None,
    keep_checkpoints=0,
) -> None:
    """The `evolve` command's work, with its options as `cli.evolve` parsed them: the run
    started (new, resumed or branched), run with progress, and its end printed."""
    logdir, resume = check_path(logdir, "--logdir"), check_path(resume, "--resume")
    config_file = check_path(config, "--config")
    wandb_project = wandb_option(wandb, wandb_project)
    TERMINATED.clear()  # this command's SIGTERM, not an earlier one's
    bounds = bounds_option(
        max_time, patience, snapshot_every, (stop_metric, stop_min_delta, stop_warmup, stop_mode)
    )
    if keep_checkpoints < 0:
        fail(f"--keep-checkpoints must be >= 0 (0: none kept), got {keep_checkpoints}")
    if print_config:
        print_resolved_config(
            config_file,
            from_run,
            resume,
            preset,
            settings,
            generations=generations,
            device=device,
            scenario=scenario,
            budget=budget,
            objective=objective_value(objective),
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
                ev, run_dir, saved = start_evolve(
                    stack,
                    scenario=scenario,
                    budget=budget,
                    objective=objective_value(objective),
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
                    keep_checkpoints=keep_checkpoints,
                )
                if shards is not None:
                    print_shard_traffic(ev.ctx.evaluator)
            if bounds is not None and bounds.reason is not None:
                console.print(
                    bound_line(bounds, ev, run_dir), markup=False, highlight=False, soft_wrap=True
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
