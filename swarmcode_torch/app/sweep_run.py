"""A sweep from the command line (`swarmcode-torch sweep`): its options checked, its runs
planned, run one after another here or as Ray tasks (`distributed.run_tasks`), each through
the one start-up path (`session`), then its table and plot written."""

from __future__ import annotations

import math
from contextlib import ExitStack
from pathlib import Path

import typer
from rich.markup import escape

from ..sim.scenario import ScenarioError
from . import session
from .eta import Eta
from .signals import TERMINATED, terminate_as_interrupt
from .terminal import (
    Failed,
    check_path,
    console,
    err,
    execute,
    fail,
    need_ray,
    os_fail,
    set_threads_option,
)


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
    budgets: str,
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
    wandb: bool = False,
    wandb_project: str = "swarmcode-torch",
) -> None:
    """The body of `swarmcode-torch sweep` (its options as parsed)."""
    from .evolve_start import wandb_option

    set_threads_option(threads)
    import time

    from ..coevo.config import with_overrides
    from ..sim.scenario import read_scenario
    from .files import SWEEP_LOCK_FILE, TABLE_MD, RunError
    from .locks import RunLock
    from .runconfig import check_config
    from .settings import option_names
    from .summary import read_summary
    from .sweep import table_rows, write_outputs

    logdir, out = check_path(logdir, "--logdir"), check_path(out, "--out")
    TERMINATED.clear()
    budget_list = parse_list(budgets, float, "--budgets")
    seed_list = parse_list(seeds, int, "--seeds")
    if checkpoint_every < 1 or log_every < 1:
        fail("--checkpoint-every and --log-every must be >= 1")
    on_ray = sweep_ray_options(workers, cpus_per_run, gpus_per_run, ray_address, device)
    project = wandb_option(wandb, wandb_project)  # before anything is made
    if logdir is not None and out is not None:
        fail(
            f"--logdir and --out cannot both be given: --out is the sweep directory itself "
            f"({out}), --logdir the directory a new one is made in ({logdir})"
        )
    if logdir is not None and logdir.exists() and not logdir.is_dir():
        fail(f"--logdir {logdir} is not a directory")
    out = out or (logdir or Path("runs")) / f"sweep-{time.strftime('%Y%m%d-%H%M%S')}"
    names = option_names({"seed": "--seeds", "budget": "--budgets"})
    try:
        base = session.resolve_config(
            preset,
            settings,
            names,
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
        scen, data = read_scenario(base.scenario)
        for b in budget_list:
            for sd in seed_list:
                check_config(with_overrides(base, budget=b, seed=sd), scen, names)
    except (ScenarioError, ValueError) as e:
        fail(str(e))
    if out.exists() and not out.is_dir():
        fail(f"--out {out} is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        os_fail(e, f"--out {out}: cannot make the sweep directory")
    runs = []
    with ExitStack() as stack:
        try:
            stack.enter_context(RunLock(out, SWEEP_LOCK_FILE))
        except RunError as e:
            fail(str(e))
        except OSError as e:
            os_fail(e, f"--out {out}: cannot lock the sweep directory")
        plans = [
            plan_sweep_run(out, with_overrides(base, budget=b, seed=sd), scen, data)
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
        failed: list[tuple[str, str]] = []
        wb = {id(p): sweep_wandb(project, p) for p in plans}
        if on_ray is None:
            eta, ran = Eta(sum(p[4] != "done" for p in plans)), 0
            for p in plans:
                b, sd, run_dir, cfg, state = p
                if state != "done":
                    run_sweep_run(
                        run_dir, cfg, data, state, checkpoint_every, log_every, again, wb[id(p)]
                    )
                    ran += 1
                    console.print(
                        f"{run_dir.name}: finished ({ran} of {eta.total} runs)  {eta.text(ran)}",
                        markup=False,
                        highlight=False,
                    )
                runs.append((b, sd, run_dir))
        else:
            ray_workers, cpus, gpus, address = on_ray
            runs, failed = sweep_on_ray(
                plans,
                data,
                checkpoint_every,
                log_every,
                again,
                ray_workers,
                cpus,
                gpus,
                address,
                wb,
            )
            if not runs:
                fail(
                    f"every run of the sweep failed ({failed[0][0]}: {failed[0][1]}); fix the "
                    f"cause, then run it again: {again}"
                )
        try:
            for _, _, run_dir in runs:
                read_summary(run_dir)  # every figure of the table is checked
            rows = table_rows(runs)
            paths = write_outputs(rows, out)
        except (RunError, ValueError) as e:
            fail(str(e))
        except OSError as e:
            os_fail(e, f"--out {out}: cannot write the table")
    console.print((out / TABLE_MD).read_text(), highlight=False, markup=False)
    console.print(
        "Wrote " + ", ".join(str(p) for p in paths), highlight=False, markup=False, soft_wrap=True
    )
    if failed:
        names = ", ".join(name for name, _ in failed)
        fail(
            f"{len(failed)} of {len(plans)} runs failed ({names}); the table has the "
            f"{len(runs)} that finished; fix the cause, then resume them: {again}"
        )


def sweep_wandb(project: str | None, plan) -> tuple[str, dict] | None:
    """(W&B project, `wandb.init` keywords) of a run of a sweep (`plan`: `plan_sweep_run`'s),
    None without --wandb: the sweep's group and tags (`wandb_runs.sweep_init`) and the W&B id of
    its run directory here, also when a node without --out runs it in a directory of its own."""
    if project is None:
        return None
    from .reporting import _wandb_run_id
    from .wandb_runs import sweep_init

    b, sd, run_dir = plan[:3]
    return project, {**sweep_init(run_dir.parent, b, sd), "id": _wandb_run_id(run_dir)}


def sweep_ray_options(
    workers: int, cpus: float | None, gpus: float | None, address: str | None, device: str | None
):
    """(workers, CPUs per run, GPUs per run, address) of a sweep on Ray, or None for the runs
    one after the other in this process; a one-line error for bad values or Ray options without
    Ray."""
    if workers < 1:
        fail(f"--workers must be >= 1, got {workers}")
    if workers == 1 and address is None:
        if cpus is not None or gpus is not None:
            fail(
                "--cpus-per-run and --gpus-per-run are for runs on Ray: use them with "
                "--workers N > 1 or --ray-address"
            )
        return None
    for name, v in (("--cpus-per-run", cpus), ("--gpus-per-run", gpus)):
        if v is not None and not (v >= 0 and math.isfinite(v)):
            fail(f"{name} must be a finite number >= 0, got {v}")
    cpus = 1.0 if cpus is None else cpus
    gpus = 0.0 if gpus is None else gpus
    if gpus > 1 and gpus != int(gpus):
        fail(f"--gpus-per-run above 1 must be a whole number of GPUs, got {gpus:g}")
    if device is not None and device.startswith("cuda") and gpus == 0:
        fail(
            f"--device {device} on Ray needs --gpus-per-run > 0 (each run reserves its share "
            "of a GPU; Ray hides the GPUs from a run that reserves none)"
        )
    need_ray(f"--workers {workers}" if workers > 1 else "--ray-address")
    return workers, cpus, gpus, address


def sweep_on_ray(
    plans,
    data: bytes,
    checkpoint_every: int,
    log_every: int,
    again: str,
    workers: int,
    cpus: float,
    gpus: float,
    address: str | None,
    wb: dict | None = None,
):
    """Run the unfinished runs of a sweep as Ray tasks (`sweep_task`, up to `workers` at once),
    a line as each ends; ([(budget, seed, run directory)] of the finished runs, in the sweep's
    order, [(run name, error)] of the failed ones)."""
    from .distributed import RayUnavailable, check_resources, ray_session, run_tasks
    from .unshared import mark_storage, read_tree, write_tree

    todo = [p for p in plans if p[4] != "done"]
    out = todo[0][2].parent if todo else Path()
    try:
        token = mark_storage(out) if todo else ""
        resume = {id(p): read_tree(p[2]) for p in todo if p[4] == "resume"}
    except OSError as e:
        os_fail(e, f"--out {out}: cannot prepare the runs for Ray")
    # absolute paths: a worker's working directory may not be this one; a run to resume
    # carries its files, for a node that does not see --out (`unshared`)
    jobs = [
        (
            run_dir.resolve(),
            cfg,
            data,
            state,
            checkpoint_every,
            log_every,
            again,
            token,
            resume.get(id(p)),
            (wb or {}).get(id(p)),
        )
        for p in todo
        for _, _, run_dir, cfg, state in [p]
    ]
    what = f"--workers {workers}" if workers > 1 else "--ray-address"
    sent_back: set[int] = set()
    eta = Eta(len(jobs))

    def on_result(i: int, value) -> str | None:
        if isinstance(value, tuple):  # ran on a node without --out: its files, written here
            error, files = value
            write_tree(todo[i][2], files)
            sent_back.add(i)
            return error
        return value

    def on_finish(i: int, error: str | None, n: dict) -> None:
        name = todo[i][2].name
        counts = f"{n['done']} done, {n['running']} running, {n['failed']} failed of {n['total']}"
        if i in sent_back:
            counts += f"; it ran where {out.resolve()} is not, its files were written here"
        counts += f")  {eta.text(n['done'] + n['failed'])}"
        if error is None:
            console.print(
                f"{name}: finished ({counts}", markup=False, highlight=False, soft_wrap=True
            )
        else:
            console.print(
                f"{name}: failed: {error} ({counts}", markup=False, highlight=False, soft_wrap=True
            )

    errors: list = []
    terminated: list = []
    if jobs:
        try:
            with ray_session(address, what) as ray, terminate_as_interrupt() as terminated:
                check_resources(
                    ray,
                    {"CPU": cpus, "GPU": gpus},
                    f"a run with --cpus-per-run {cpus:g} and --gpus-per-run {gpus:g}",
                )
                console.print(
                    f"Ray: {len(jobs)} runs, up to {workers} at once ({cpus:g} CPU, "
                    f"{gpus:g} GPU each)",
                    markup=False,
                    highlight=False,
                )
                errors = run_tasks(
                    sweep_task,
                    jobs,
                    workers=workers,
                    num_cpus=cpus,
                    num_gpus=gpus,
                    on_finish=on_finish,
                    what=what,
                    on_result=on_result,
                )
        except RayUnavailable as e:
            fail(str(e))
        except KeyboardInterrupt:
            how = "Terminated" if terminated else "Interrupted"
            err.print(
                f"{how}: the running runs were stopped after writing their checkpoints; "
                f"continue with: {again}",
                markup=False,
                highlight=False,
                soft_wrap=True,
            )
            raise typer.Exit(code=143 if terminated else 130) from None
    failed_at = {id(p): e for p, e in zip(todo, errors) if e is not None}
    finished = [p[:3] for p in plans if id(p) not in failed_at]
    failed = [(p[2].name, failed_at[id(p)]) for p in plans if id(p) in failed_at]
    return finished, failed


def sweep_task(
    run_dir: Path,
    cfg,
    data: bytes,
    state: str,
    checkpoint_every: int,
    log_every: int,
    again: str,
    token: str = "",
    files: dict | None = None,
    wb: tuple[str, dict] | None = None,
):
    """One run of a sweep as a Ray task (`distributed.run_tasks`): `run_sweep_run`, as the
    sweep runs it in this process. None when the run finished; else its error in one line (a
    failed start or write; a stop by Ctrl-C or SIGTERM, after its checkpoint was written).
    On a node that does not see the sweep directory (its mark does not hold `token`), the run
    is made in a local temporary directory from `files` and the task returns (error, the run
    directory's files) for the driver to write (`unshared`)."""
    from .unshared import run_elsewhere, sees_storage

    if token and not sees_storage(run_dir.parent, token):
        return run_elsewhere(
            run_dir,
            files,
            lambda local: sweep_task(
                local, cfg, data, state, checkpoint_every, log_every, again, wb=wb
            ),
        )
    try:
        run_sweep_run(run_dir, cfg, data, state, checkpoint_every, log_every, again, wb)
    except Failed as e:
        return e.message
    except typer.Exit as e:
        return f"stopped (exit {e.exit_code}) after writing its checkpoint"
    except Exception as e:  # noqa: BLE001 - the run's error; the sweep's other runs go on
        return " ".join(f"{type(e).__name__}: {e}".split())
    return None


def plan_sweep_run(out: Path, cfg, scenario, data: bytes):
    """(budget, seed, run directory, config, state) of one run of a sweep (`sweep.plan_run`),
    state 'done', 'resume' or 'new'; a one-line error for a run it cannot take over."""
    from .files import RunError
    from .sweep import plan_run, run_name

    try:
        p = plan_run(out, cfg, scenario)
    except (ScenarioError, RunError, ValueError) as e:
        fail(str(e))
    except OSError as e:
        os_fail(e, f"{out / run_name(cfg.budget, cfg.seed)}: cannot read the run")
    if p.state == "done":
        more = (
            f" (it has {p.done}, more than the {cfg.generations} asked for)"
            if p.done > cfg.generations
            else ""
        )
        console.print(f"{p.run_dir.name}: already done{more}", markup=False, highlight=False)
    return p.budget, p.seed, p.run_dir, p.cfg, p.state


def run_sweep_run(
    run_dir: Path,
    cfg,
    data: bytes,
    state: str,
    checkpoint_every: int,
    log_every: int,
    again: str,
    wb: tuple[str, dict] | None = None,
) -> None:
    """One run of a sweep, started (`state` 'new': its config and `data` checked by the sweep)
    or resumed through `session`, then run with the command line's progress and messages (and
    logged to W&B with `wb`, `sweep_wandb`'s)."""
    from .files import RunError

    def make_dir(ev) -> Path:
        run_dir.mkdir(exist_ok=True)
        return run_dir

    with ExitStack() as stack:
        try:
            if state == "resume":
                start = session.start_resume(stack, run_dir, generations=cfg.generations)
            else:  # a config error leaves no directory behind
                start = session.start_new(stack, cfg, make_dir, data=data)
            ev, saved = start.ev, start.saved
        except (ScenarioError, RunError, ValueError) as e:
            fail(str(e))
        except OSError as e:
            os_fail(e, f"{run_dir}: cannot start the run")
        console.print(
            f"[bold]{escape(run_dir.name)}[/]: generation {ev.state.generation} -> "
            f"{cfg.generations}",
            soft_wrap=True,
        )
        execute(
            ev,
            run_dir,
            checkpoint_every,
            log_every,
            saved=saved,
            again=again,
            wandb_project=wb[0] if wb else None,
            wandb_init=wb[1] if wb else None,
        )
