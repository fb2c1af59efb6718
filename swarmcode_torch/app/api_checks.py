"""The Python API's keywords checked before a run starts (`api.evolve`, `api.resume`): the
folder, the declared options and their bounds, the reporters and the callback, a user fitness
function as a run calls it, the W&B reporter and the run's stopping bounds."""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any

from ..coevo.evaluation import ScoreFn, score_fn_name
from . import session
from .files import RunError
from .optspec import Intervals, Values, check_values
from .run_options import EVOLVE_OPTIONS


def checked_logdir(logdir) -> Path:
    """`logdir` as a folder; RunError for an empty one ('' would write into the working
    directory) or one that is not a path."""
    if not isinstance(logdir, (str, os.PathLike)) or not str(os.fspath(logdir)).strip():
        raise RunError(f"logdir must be a folder path, got {logdir!r:.60}")
    return Path(logdir)


def declared(**given: Any) -> Values:
    """The API's keywords that `run_options` declares (checkpoint_every=, patience=, ...) as
    `Values`, each checked against its declared bound (`optspec.check_values`): TypeError for
    one that is not an integer, ValueError below its bound."""
    opts = [o for o in EVOLVE_OPTIONS if o.name in given]
    values = Values(opts, given)
    check_values(opts, values)
    return values


def declared_intervals(**given: Any) -> Intervals:
    """The `Intervals` of the API's keywords (checkpoint_every=, render_every=, ...; the others
    at their defaults), each checked (`declared`)."""
    return declared(**given).intervals(EVOLVE_OPTIONS)


def check_hooks(callback, reporters) -> list:
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


def checked_fitness(fitness: ScoreFn | None) -> ScoreFn | None:
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


def wandb_reporters(project: str | None, run_dir: Path | None, render_every: int) -> list:
    """[a `WandbReporter` of `project` for `run_dir`], or [] for None; ImportError naming the
    extra, before anything runs."""
    from .reporting import WandbReporter

    return [] if project is None else [WandbReporter(project, run_dir, render_every=render_every)]


def run_bounds(max_time, patience, stop=(), callback=None) -> session.Bounds | None:
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
