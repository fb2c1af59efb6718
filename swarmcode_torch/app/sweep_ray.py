"""A sweep's runs as Ray tasks (`swarmcode-torch sweep --workers N` or `--ray-address`): the
Ray options checked (`sweep_ray_options`), the unfinished runs submitted and reported as each
ends (`sweep_on_ray`), and one run as a task (`sweep_task`), also on a node that does not see
the sweep directory (`unshared`). `sweep_run` plans the runs and writes the table."""

from __future__ import annotations

import math
from pathlib import Path

import typer

from .signals import terminate_as_interrupt
from .sweep_one import run_sweep_run, sweep_progress
from .terminal import Failed, console, err, fail, need_ray, os_fail


def sweep_ray_options(
    workers: int, cpus: float | None, gpus: float | None, address: str | None, device: str | None
):
    """(workers, CPUs per run, GPUs per run, address) of a sweep on Ray, or None for the runs
    one after the other in this process; a one-line error for bad values or Ray options without
    Ray (--workers >= 1 is checked with the other declared bounds, `run_options`)."""
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
    todo = [p for p in plans if p[4] != "done"]
    out, jobs = _ray_jobs(todo, data, checkpoint_every, log_every, again, wb)
    what = f"--workers {workers}" if workers > 1 else "--ray-address"
    shown = _RayProgress(plans, todo, out)
    errors: list = []
    if jobs:
        errors = _run_on_ray(jobs, workers, cpus, gpus, address, what, again, shown)
    failed_at = {id(p): e for p, e in zip(todo, errors) if e is not None}
    finished = [p[:3] for p in plans if id(p) not in failed_at]
    failed = [(p[2].name, failed_at[id(p)]) for p in plans if id(p) in failed_at]
    return finished, failed


def _ray_jobs(todo, data, checkpoint_every, log_every, again, wb) -> tuple[Path, list]:
    """(the sweep directory, the arguments of `sweep_task` of each run of `todo`, the unfinished
    runs); a one-line error when the sweep directory cannot be marked or a run read."""
    from .unshared import mark_storage, read_tree

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
            (
                run_dir.resolve(),
                cfg,
                data,
                state,
                checkpoint_every,
                log_every,
                again,
                (wb or {}).get(id(p)),
            ),
            token,
            resume.get(id(p)),
        )
        for p in todo
        for _, _, run_dir, cfg, state, _ in [p]
    ]
    return out, jobs


class _RayProgress:
    """What the sweep prints as each of its Ray tasks ends, and the files of a run that ran on
    a node without --out written here."""

    def __init__(self, plans, todo, out: Path):
        self.todo, self.out = todo, out
        self.sent_back: set[int] = set()
        self.shown = sweep_progress(plans)  # the sweep's times as each run ends
        self.at = [k for k, p in enumerate(plans) if p[4] != "done"]  # todo[i] is plans[at[i]]

    def on_result(self, i: int, value) -> str | None:
        from .unshared import write_tree

        if isinstance(value, tuple):  # ran on a node without --out: its files, written here
            error, files = value
            write_tree(self.todo[i][2], files)
            self.sent_back.add(i)
            return error
        return value

    def on_finish(self, i: int, error: str | None, n: dict) -> None:
        name = self.todo[i][2].name
        counts = f"{n['done']} done, {n['running']} running, {n['failed']} failed of {n['total']}"
        if i in self.sent_back:
            counts += f"; it ran where {self.out.resolve()} is not, its files were written here"
        self.shown.finished(self.at[i])
        counts += f")  {self.shown.times()}"
        if error is None:
            console.print(
                f"{name}: finished ({counts}", markup=False, highlight=False, soft_wrap=True
            )
        else:
            console.print(
                f"{name}: failed: {error} ({counts}", markup=False, highlight=False, soft_wrap=True
            )


def _run_on_ray(jobs, workers, cpus, gpus, address, what, again, shown: _RayProgress) -> list:
    """`jobs` run as Ray tasks, up to `workers` at once; the error of each (None: finished). A
    one-line error without Ray; Ctrl-C or SIGTERM: the running runs stop after writing their
    checkpoints, and the command exits (130, 143)."""
    from .distributed import RayUnavailable, check_resources, ray_session, run_tasks

    terminated: list = []
    errors: list = []
    try:
        with ray_session(address, what) as ray, terminate_as_interrupt() as terminated:
            check_resources(
                ray,
                {"CPU": cpus, "GPU": gpus},
                f"a run with --cpus-per-run {cpus:g} and --gpus-per-run {gpus:g}",
            )
            console.print(
                f"Ray: {len(jobs)} runs, up to {workers} at once ({cpus:g} CPU, {gpus:g} GPU each)",
                markup=False,
                highlight=False,
            )
            errors = run_tasks(
                sweep_task,
                jobs,
                workers=workers,
                num_cpus=cpus,
                num_gpus=gpus,
                on_finish=shown.on_finish,
                what=what,
                on_result=shown.on_result,
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
    return errors


def sweep_task(run: tuple, token: str = "", files: dict | None = None):
    """One run of a sweep as a Ray task (`distributed.run_tasks`): `run_sweep_run(*run)` (`run`:
    its arguments, the run directory first), as the sweep runs it in this process. None when
    the run finished; else its error in one line (a failed start or write; a stop by Ctrl-C or
    SIGTERM, after its checkpoint was written). On a node that does not see the sweep directory
    (its mark does not hold `token`), the run is made in a local temporary directory from
    `files` and the task returns (error, the run directory's files) for the driver to write
    (`unshared`)."""
    from .unshared import run_elsewhere, sees_storage

    run_dir = run[0]
    if token and not sees_storage(run_dir.parent, token):
        return run_elsewhere(run_dir, files, lambda local: sweep_task((local, *run[1:])))
    try:
        run_sweep_run(*run)
    except Failed as e:
        return e.message
    except typer.Exit as e:
        return f"stopped (exit {e.exit_code}) after writing its checkpoint"
    except Exception as e:  # noqa: BLE001 - the run's error; the sweep's other runs go on
        return " ".join(f"{type(e).__name__}: {e}".split())
    return None
