"""Ray: the runs of a sweep as Ray tasks, and each generation's evaluation in shards on Ray actors
(`ray_shards`); connecting to Ray in `ray_cluster`. Every public name is importable from here.

Ray is optional (`pip install -e ".[ray]"` in the source tree) and imported only when one of these is
used, never when the package is imported. docs/DISTRIBUTED.md shows local, multi-node and Slurm
clusters.

- `run_tasks` runs a function once per job as Ray tasks, at most `workers` at once, each with
  its CPUs and GPUs (the sweep's per-run function, `sweep_ray.sweep_task`), and reports each as it
  ends; a failed job does not stop the others.
- `ShardedEvaluator` is an evaluator for `evolve.Context.evaluator`: it cuts a generation's
  evaluation plan (`evaluation.plan_evaluation`, drawn in the driver) into shards of whole
  evaluations, ships each shard's `SimBatch` (the genome rows its teams use, the teams, their
  environments; `pack_batch`) to one Ray actor, which simulates it with its own tick function on its own
  device (`evaluation.simulate_batch`), and gathers the per-environment metrics. The rollouts
  draw their in-episode randomness from each environment's seed, and every draw of the
  generator stays in the driver, so the scores are those of the unsharded run.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import torch

from .ray_cluster import (
    INTERRUPT_GRACE,
    LOCAL_NODE_IP,
    RAY_CONNECT_TIMEOUT,
    RAY_INSTALL,
    RAY_START_TIMEOUT,
    RayUnavailable,
    ShardError,
    check_ray_address,
    check_resources,
    one_line,
    ray_session,
    require_ray,
    wait_started,
)
from .ray_shards import (
    EvalShard,
    ShardedEvaluator,
    ShardSpec,
    _pack_tensor,
    _unpack_tensor,
    pack_batch,
    pack_metrics,
    shard_bounds,
    sharded_evaluation,
    unpack_batch,
    unpack_metrics,
)

__all__ = [
    "EvalShard",
    "INTERRUPT_GRACE",
    "LOCAL_NODE_IP",
    "RAY_CONNECT_TIMEOUT",
    "RAY_INSTALL",
    "RAY_START_TIMEOUT",
    "RayUnavailable",
    "ShardError",
    "ShardSpec",
    "ShardedEvaluator",
    "_pack_tensor",
    "_unpack_tensor",
    "check_ray_address",
    "check_resources",
    "one_line",
    "pack_batch",
    "pack_metrics",
    "ray_session",
    "require_ray",
    "run_tasks",
    "shard_bounds",
    "sharded_evaluation",
    "unpack_batch",
    "unpack_metrics",
    "wait_started",
]


# ------------------------------------------------------------------ tasks (sweeps)
def _run_task(fn: Callable, threads: int, hide_gpus: bool, *args):
    """Body of a Ray task: torch's CPU threads set to the task's CPUs, the GPUs hidden from a
    task that reserved none (so that device 'auto' does not take one), then fn(*args)."""
    if hide_gpus:
        os.environ["CUDA_VISIBLE_DEVICES"] = ""
    torch.set_num_threads(max(1, threads))
    return fn(*args)


def _started() -> int:
    """A probe task: returns as soon as a worker runs it."""
    return os.getpid()


def run_tasks(
    fn: Callable,
    jobs: list[tuple],
    *,
    workers: int,
    num_cpus: float,
    num_gpus: float,
    on_finish: Callable[[int, str | None, dict], None] | None = None,
    what: str = "running tasks on Ray",
    on_result: Callable[[int, Any], str | None] | None = None,
) -> list[str | None]:
    """fn(*job) for every job as a Ray task (Ray connected: `ray_session`), at most `workers` at
    once, each reserving `num_cpus` CPUs and `num_gpus` GPUs; fn returns None when the job
    finished, else its error in one line. A task is not retried: its job is reported failed
    (a dead worker: the Ray error, in one line) and the others go on. `on_finish(index, error,
    counts)` is called as each ends (counts: done, running, failed, total). When fn returns
    more than its error, `on_result(index, value)` turns what job `index` returned into its error
    here, in the driver (writing files the task sent back; an exception it raises is the job's
    error). Returns each job's error (None: finished). Ctrl-C (KeyboardInterrupt) cancels the
    running tasks, which get KeyboardInterrupt in turn (a run writes its checkpoint), waits up to INTERRUPT_GRACE seconds
    for them, and re-raises. Before any job, as many probe tasks as will run at once (with the
    same CPUs and GPUs) must start within SWARMCODE_RAY_START_TIMEOUT seconds (`wait_started`),
    else RayUnavailable naming `what` (Ray would wait forever for workers that cannot start)."""
    ray = require_ray(what)
    if jobs:
        probe = ray.remote(num_cpus=num_cpus, num_gpus=num_gpus, max_retries=0)(_started)
        n = min(workers, len(jobs))
        refs = [probe.remote() for _ in range(n)]
        try:
            wait_started(ray, refs, f"{n} worker{'s' if n > 1 else ''} for the runs", what)
        except RayUnavailable:
            for ref in refs:
                try:
                    ray.cancel(ref, force=True)
                except Exception:  # noqa: BLE001 - already gone
                    pass
            raise
    task = ray.remote(num_cpus=num_cpus, num_gpus=num_gpus, max_retries=0)(_run_task)
    threads = max(1, int(num_cpus))
    errors: list[str | None] = [None] * len(jobs)
    pending = list(range(len(jobs)))
    running: dict = {}
    done = failed = 0
    try:
        while pending or running:
            while pending and len(running) < workers:
                i = pending.pop(0)
                running[task.remote(fn, threads, num_gpus == 0, *jobs[i])] = i
            ready, _ = ray.wait(list(running), num_returns=1)
            for ref in ready:
                i = running.pop(ref)
                errors[i] = _task_error(ray, ref, i, on_result)
                if errors[i] is None:
                    done += 1
                else:
                    failed += 1
                if on_finish is not None:
                    on_finish(
                        i,
                        errors[i],
                        {
                            "done": done,
                            "running": len(running),
                            "failed": failed,
                            "total": len(jobs),
                        },
                    )
    except KeyboardInterrupt:
        refs = list(running)
        for ref in refs:
            ray.cancel(ref)
        if refs:
            ended, _ = ray.wait(refs, num_returns=len(refs), timeout=INTERRUPT_GRACE)
            if on_result is not None:  # what the stopped tasks sent back (their checkpoints)
                for ref in ended:
                    _task_error(ray, ref, running[ref], on_result)
        raise
    return errors


def _task_error(ray, ref, i: int, on_result: Callable[[int, Any], str | None] | None):
    """The error of task `ref` (job `i`) that has ended, in one line; None when it finished."""
    try:
        value = ray.get(ref)
        return value if on_result is None else on_result(i, value)
    except ray.exceptions.RayError as e:
        return one_line(e)
    except Exception as e:  # noqa: BLE001 - on_result's failure is this job's error
        return one_line(e)
