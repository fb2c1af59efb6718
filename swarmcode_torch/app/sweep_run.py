"""A sweep from the command line (`swarmcode-torch sweep`): its options checked, its runs
planned, run one after another here or as Ray tasks (`sweep_ray`), each through the one
start-up path (`session`), then its table and plot written."""

from __future__ import annotations

import math
from contextlib import ExitStack
from pathlib import Path

from ..sim.scenario import ScenarioError
from . import session
from .run_options import DEFAULT_BUDGETS
from .signals import TERMINATED
from .sweep_one import run_sweep_run, sweep_progress
from .terminal import check_path, console, fail, os_fail, set_threads_option


def parse_list(text: str, kind, option: str) -> list:
    try:
        vals = [kind(x) for x in text.split(",") if x.strip()]
    except ValueError:
        fail(f"{option} expects a comma-separated list of numbers, got {text!r}")
    if not vals:
        fail(f"{option} is empty")
    for v in vals:
        if kind is float and not math.isfinite(v):
            fail(f"{option}: {v} is not a finite number")
        if vals.count(v) > 1:
            fail(f"{option} lists {v:g} twice (each run is one budget and one seed)")
    return vals


def run_sweep(
    budgets: str | None,
    seeds: str,
    objective: str | None,
    scenario,
    generations,
    population,
    swarm_size,
    trials,
    ticks,
    device,
    compile,
    logdir: str | None,
    out: str | None,
    checkpoint_every: int,
    log_every: int,
    preset,
    settings,
    workers: int,
    cpus_per_run,
    gpus_per_run,
    ray_address,
    threads,
    grid: list[str] | None = None,
    config: str | None = None,
    wandb: bool = False,
    wandb_project: str = "swarmcode-torch",
) -> None:
    """The body of `swarmcode-torch sweep`: its options as parsed (`run_options.SWEEP_OPTIONS`,
    their declared bounds checked); `grid`: the --grid KEY=V1,V2 pairs, `sweep_grid`; `config`:
    --config FILE, the runs' settings to start from; `wandb`, `wandb_project`: each run logged
    to W&B, grouped by the sweep, `wandb_runs`."""
    from .evolve_start import wandb_option
    from .sweep_ray import sweep_ray_options

    set_threads_option(threads)
    from .sweep_grid import point_name, with_point

    logdir, out = check_path(logdir, "--logdir"), check_path(out, "--out")
    config_file = check_path(config, "--config")
    TERMINATED.clear()
    budget_list = None if budgets is None else parse_list(budgets, float, "--budgets")
    seed_list = parse_list(seeds, int, "--seeds")
    on_ray = sweep_ray_options(workers, cpus_per_run, gpus_per_run, ray_address, device)
    project = wandb_option(wandb, wandb_project)  # before anything is made
    out = _sweep_dir(logdir, out)
    given = dict(
        objective=objective,
        scenario=scenario,
        generations=generations,
        population=population,
        swarm_size=swarm_size,
        trials=trials,
        ticks=ticks,
        device=device,
        compile=compile,
    )
    base, scen, data, points, budget_list, keys = _sweep_configs(
        given, grid, preset, settings, config_file, budgets, budget_list, seed_list
    )
    _make_sweep_dir(out)
    with ExitStack() as stack:
        _lock_sweep(stack, out)
        plans = [
            plan_sweep_run(out, with_point(base, pt, b, sd), scen, data, point_name(pt))
            for pt in points
            for b in budget_list
            for sd in seed_list
        ]  # every refusal before any run
        again = f"swarmcode-torch sweep with the same options and --out {out}"
        console.print(
            f"Sweep directory: {out} (resume with --out {out})",
            markup=False,
            highlight=False,
            soft_wrap=True,
        )
        wb = {id(p): sweep_wandb(project, p) for p in plans}
        runs, failed = _run_plans(plans, data, checkpoint_every, log_every, again, wb, on_ray)
        runs, paths = _write_table(runs, plans, keys, out)
    _print_end(out, paths, failed, len(plans), len(runs), again)


def _lock_sweep(stack: ExitStack, out: Path) -> None:
    """The sweep directory's sweep.lock held until `stack` closes; a one-line error when another
    process holds it or it cannot be made."""
    from .files import SWEEP_LOCK_FILE, RunError
    from .locks import RunLock

    try:
        stack.enter_context(RunLock(out, SWEEP_LOCK_FILE))
    except RunError as e:
        fail(str(e))
    except OSError as e:
        os_fail(e, f"--out {out}: cannot lock the sweep directory")


def _run_plans(plans, data, checkpoint_every, log_every, again, wb, on_ray):
    """The sweep's unfinished runs run here (`on_ray` None) or as Ray tasks (`sweep_ray`);
    ([(budget, seed, run directory)] of the finished runs, [(run name, error)] of the failed
    ones: only on Ray, where a failed run leaves the others going). A one-line error when every
    run failed."""
    from .sweep_ray import sweep_on_ray

    if on_ray is None:
        return _run_here(plans, data, checkpoint_every, log_every, again, wb), []
    ray_workers, cpus, gpus, address = on_ray
    runs, failed = sweep_on_ray(
        plans, data, checkpoint_every, log_every, again, ray_workers, cpus, gpus, address, wb
    )
    if not runs:
        fail(
            f"every run of the sweep failed ({failed[0][0]}: {failed[0][1]}); fix the "
            f"cause, then run it again: {again}"
        )
    return runs, failed


def _print_end(out: Path, paths, failed, planned: int, finished: int, again: str) -> None:
    """The sweep's table and the files written printed; then a one-line error naming the runs
    that failed, if any did."""
    from .files import TABLE_MD

    console.print((out / TABLE_MD).read_text(), highlight=False, markup=False)
    console.print(
        "Wrote " + ", ".join(str(p) for p in paths), highlight=False, markup=False, soft_wrap=True
    )
    if failed:
        names = ", ".join(name for name, _ in failed)
        fail(
            f"{len(failed)} of {planned} runs failed ({names}); the table has the "
            f"{finished} that finished; fix the cause, then resume them: {again}"
        )


def _sweep_dir(logdir: Path | None, out: Path | None) -> Path:
    """The sweep directory: --out, or a new sweep-TIME in --logdir (default runs/); a one-line
    error for both, or a --logdir that is not a directory."""
    import time

    if logdir is not None and out is not None:
        fail(
            f"--logdir and --out cannot both be given: --out is the sweep directory itself "
            f"({out}), --logdir the directory a new one is made in ({logdir})"
        )
    if logdir is not None and logdir.exists() and not logdir.is_dir():
        fail(f"--logdir {logdir} is not a directory")
    return out or (logdir or Path("runs")) / f"sweep-{time.strftime('%Y%m%d-%H%M%S')}"


def _sweep_configs(given, grid, preset, settings, config_file, budgets, budget_list, seed_list):
    """(the runs' base config, the scenario and its file's bytes, the grid's points, the
    budgets, the grid's keys) of a sweep, every run's config checked (`check_config`) before
    anything is made; a one-line error otherwise. `given`: the command's setting options,
    `config_file`: --config."""
    from ..sim.scenario import read_scenario
    from .files import RunError
    from .runconfig import check_config
    from .settings import option_names
    from .sweep_grid import grid_points, parse_grid, with_point

    names = option_names({"seed": "--seeds", "budget": "--budgets"})
    try:
        grid_spec = parse_grid(grid, given)
        if config_file is None:
            base = session.resolve_config(preset, settings, names, **given)
        else:  # as evolve --config: a bad value the file gives is named FILE: key
            from .evolve_start import config_from

            base, _, names = config_from(config_file, None, preset, settings, given)
            names["seed"] = "--seeds"
            if budgets is not None or names["budget"] == "--budget":
                names["budget"] = "--budgets"
        if budget_list is None:
            budget_list = (
                [base.budget]
                if grid_spec or config_file is not None
                else parse_list(DEFAULT_BUDGETS, float, "--budgets")
            )
        points = grid_points(grid_spec)
        scen, data = read_scenario(base.scenario)
        for pt in points:
            for b in budget_list:
                for sd in seed_list:
                    check_config(with_point(base, pt, b, sd), scen, names)
    except (ScenarioError, RunError, ValueError) as e:
        fail(str(e))
    except OSError as e:
        os_fail(e, "cannot read the config")
    return base, scen, data, points, budget_list, tuple(grid_spec)


def _make_sweep_dir(out: Path) -> None:
    """The sweep directory made (with its parents); a one-line error when it cannot be."""
    if out.exists() and not out.is_dir():
        fail(f"--out {out} is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        os_fail(e, f"--out {out}: cannot make the sweep directory")


def _run_here(plans, data, checkpoint_every, log_every, again, wb) -> list:
    """The sweep's runs (`plan_sweep_run`'s) one after the other in this process, a line as
    each starts and ends; [(budget, seed, run directory)] of every run, in order."""
    runs = []
    shown = sweep_progress(plans)
    for k, p in enumerate(plans):
        b, sd, run_dir, cfg, state, _ = p
        if state != "done":
            console.print(
                shown.line(k, run_dir.name), markup=False, highlight=False, soft_wrap=True
            )
            run_sweep_run(run_dir, cfg, data, state, checkpoint_every, log_every, again, wb[id(p)])
            shown.finished(k)
            console.print(
                f"{run_dir.name}: finished ({k + 1} of {shown.total} runs)  {shown.times()}",
                markup=False,
                highlight=False,
                soft_wrap=True,
            )
        runs.append((b, sd, run_dir))
    return runs


def _write_table(runs, plans, keys: tuple, out: Path) -> tuple[list, list]:
    """The sweep's table (Markdown, CSV) and plot written from its finished `runs`, every figure
    of their summaries checked; (the runs with their grid values, the paths written). A
    one-line error otherwise."""
    from .files import RunError
    from .summary import read_summary
    from .sweep import table_rows, write_outputs

    try:
        for _, _, run_dir in runs:
            read_summary(run_dir)  # every figure of the table is checked
        cfgs = {p[2]: p[3] for p in plans}
        runs = [(b, sd, d, {k: getattr(cfgs[d], k) for k in keys}) for b, sd, d in runs]
        rows = table_rows(runs, keys)
        paths = write_outputs(rows, out, keys)
    except (RunError, ValueError) as e:
        fail(str(e))
    except OSError as e:
        os_fail(e, f"--out {out}: cannot write the table")
    return runs, paths


def sweep_wandb(project: str | None, plan) -> tuple[str, dict] | None:
    """(W&B project, `wandb.init` keywords) of a run of a sweep (`plan`: `plan_sweep_run`'s),
    None without --wandb: the sweep's group and tags (`wandb_runs.sweep_init`) and the W&B id of
    its run directory here, also when a node without --out runs it in a directory of its own."""
    if project is None:
        return None
    from .report_wandb import _wandb_run_id
    from .wandb_runs import sweep_init

    b, sd, run_dir = plan[:3]
    return project, {**sweep_init(run_dir.parent, b, sd), "id": _wandb_run_id(run_dir)}


def plan_sweep_run(out: Path, cfg, scenario, data: bytes, prefix: str = ""):
    """(budget, seed, run directory, config, state, generations done) of one run of a sweep
    (`sweep.plan_run`; `prefix`: its grid point's part of its name), state 'done', 'resume' or
    'new'; a one-line error for a run it cannot take over."""
    from .files import RunError
    from .sweep import plan_run, run_name

    try:
        p = plan_run(out, cfg, scenario, prefix)
    except (ScenarioError, RunError, ValueError) as e:
        fail(str(e))
    except OSError as e:
        os_fail(e, f"{out / (prefix + run_name(cfg.budget, cfg.seed))}: cannot read the run")
    if p.state == "done":
        more = (
            f" (it has {p.done}, more than the {cfg.generations} asked for)"
            if p.done > cfg.generations
            else ""
        )
        console.print(f"{p.run_dir.name}: already done{more}", markup=False, highlight=False)
    return p.budget, p.seed, p.run_dir, p.cfg, p.state, p.done
