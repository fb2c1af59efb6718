"""The thread and Ray options of a run, as the process acts on them: torch's CPU threads
(`set_threads_option`), evaluation shards on Ray actors (`eval_shards_option`,
`attach_shards`, their traffic), Ray needed. The options themselves are declared in
`run_options`."""

from __future__ import annotations

import math
from contextlib import ExitStack

from rich.markup import escape

from .cli_output import console, fail
from .run_options import THREADS_HELP  # noqa: F401 - importable from here, as before


def set_threads_option(threads: int | None) -> None:
    from ..sim.runtime import set_threads

    try:
        set_threads(threads)
    except ValueError as e:
        fail(f"--{e}")


def eval_shards_option(eval_workers: int, cpus: float | None, address: str | None):
    """(workers, CPUs per worker, address) of a sharded evaluation, or None for the evaluation
    in this process; a one-line error for bad values or Ray options without Ray
    (--eval-workers >= 1 is checked with the other declared bounds, `run_options`)."""
    if eval_workers == 1 and address is None:
        if cpus is not None:
            fail(
                "--cpus-per-eval-worker is for evaluation shards on Ray: use it with "
                "--eval-workers N > 1 or --ray-address"
            )
        return None
    if cpus is not None and not (cpus > 0 and math.isfinite(cpus)):
        fail(f"--cpus-per-eval-worker must be a finite number > 0, got {cpus}")
    need_ray(f"--eval-workers {eval_workers}" if eval_workers > 1 else "--ray-address")
    return eval_workers, 1.0 if cpus is None else cpus, address


def need_ray(what: str) -> None:
    """A one-line error naming the extra to install when Ray is missing."""
    from .distributed import RayUnavailable, require_ray

    try:
        require_ray(what)
    except RayUnavailable as e:
        fail(str(e))


def attach_shards(stack: ExitStack, ev, workers: int, cpus: float, address: str | None) -> None:
    """Evaluate `ev`'s generations in shards on Ray actors until `stack` closes."""
    from .distributed import RayUnavailable, sharded_evaluation

    try:
        evaluator = stack.enter_context(sharded_evaluation(ev, workers, address, cpus))
    except RayUnavailable as e:
        fail(str(e))
    where = sorted(set(evaluator.where))
    console.print(
        f"Evaluation: {workers} shards on Ray actors ({escape('; '.join(where))})",
        highlight=False,
        soft_wrap=True,
    )


def print_shard_traffic(evaluator) -> None:
    stats = getattr(evaluator, "stats", None)
    if not stats:
        return
    n = len(stats)
    sent = sum(s["bytes_sent"] for s in stats) / n
    back = sum(s["bytes_received"] for s in stats) / n
    console.print(
        f"Evaluation shards: {sent / 1024:.1f} KiB sent and {back / 1024:.1f} KiB "
        f"received per generation (pickled, mean of {n} generations)",
        highlight=False,
        markup=False,
    )
