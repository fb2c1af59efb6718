"""Stops a run may take after a generation besides --max-time and plain --patience
(`session.Bounds.stops`): early stopping on a chosen metric with a minimum improvement and a
warm-up (`MetricStop`), and a Python callback that asks the run to stop (`CallbackStop`).

A stop is checked after the generation's records are written (`session.run`), so a run it
stops ends as one stopped by --patience: its checkpoint written (resume continues it), the
"stop" of summary.json recorded, a line saying why."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..coevo.evolve import Evolution, GenerationResult
from . import records
from .run_record import app_record

#: The metric the run's own best team gives (`GenerationResult.best`): what --patience alone
#: watches, and the default of --stop-metric.
BEST = "best/fitness"
MODES = ("max", "min")


def metric_names() -> tuple[str, ...]:
    """Every metric --stop-metric may name: the run's best team's fitness and the tags of
    metrics.csv (`reporting.SCALAR_TAGS`)."""
    from .reporting import SCALAR_TAGS

    return (BEST, *SCALAR_TAGS)


def metric_value(result: GenerationResult, metric: str) -> float:
    """`metric`'s value of one recorded generation (`records.step`'s result)."""
    if metric == BEST:
        return float(result.best["fitness"]) if result.best else math.nan
    return float(records.scalars(result)[metric])


class MetricStop:
    """Stop when `metric` has not improved by more than `min_delta` for `patience` generations,
    counted from generation `warmup` on (the generations before it are not watched): in mode
    "max" an improvement is a value above the best so far plus `min_delta`, in "min" below it
    minus `min_delta`. A NaN value is no improvement. Resumed, it first reads the run's earlier
    values back (`start`)."""

    reason = "patience"

    def __init__(
        self,
        patience: int,
        metric: str = BEST,
        min_delta: float = 0.0,
        warmup: int = 0,
        mode: str = "max",
    ):
        check_metric_stop(patience, metric, min_delta, warmup, mode)
        self.patience, self.metric, self.min_delta = patience, metric, float(min_delta)
        self.warmup, self.mode = warmup, mode
        self.best: float | None = None
        self.best_generation: int | None = None
        self.last: int | None = None

    def observe(self, generation: int, value: float) -> None:
        self.last = generation
        if generation < self.warmup or math.isnan(value):
            return
        if self.best is None:
            better = True
        elif self.mode == "max":
            better = value > self.best + self.min_delta
        else:
            better = value < self.best - self.min_delta
        if better:
            self.best, self.best_generation = value, generation

    def start(self, ev: Evolution, run_dir: Path | None) -> None:
        """A resumed run: the values of its earlier generations, from its metrics.csv (of
        `best/fitness`: the run's best team so far, found at its generation)."""
        from .files import METRICS_FILE
        from .reporting import read_metrics_csv

        before = ev.state.generation
        if self.metric == BEST:
            best = app_record(ev).best
            if best is not None and int(best["generation"]) >= self.warmup:
                self.best, self.best_generation = float(best["fitness"]), int(best["generation"])
            return
        if run_dir is None or before == 0:
            return
        path = Path(run_dir) / METRICS_FILE
        if not path.is_file():
            return
        for row in read_metrics_csv(path)[0]:
            v = row.get(self.metric)
            if row["generation"] < before:
                self.observe(row["generation"], math.nan if v is None else float(v))

    def check(self, ev: Evolution, result: GenerationResult) -> str | None:
        self.observe(result.generation, metric_value(result, self.metric))
        start = self.warmup if self.best_generation is None else self.best_generation
        if result.generation - start >= self.patience:
            return self.reason
        return None

    def record(self) -> dict:
        return {
            "patience": self.patience,
            "metric": self.metric,
            "min_delta": self.min_delta,
            "warmup": self.warmup,
            "mode": self.mode,
            "best_value": self.best,
            "best_generation": self.best_generation,
        }

    def why(self) -> str:
        delta = f" by more than {self.min_delta:g}" if self.min_delta else ""
        since = (
            f"since generation {self.best_generation} ({self.best:.4g})"
            if self.best_generation is not None
            else f"since the warm-up ended (generation {self.warmup})"
        )
        return (
            f"{self.metric} has not improved{delta} for {self.patience} generations {since} "
            f"(--patience {self.patience}, --stop-metric {self.metric})"
        )


def check_metric_stop(patience, metric, min_delta, warmup, mode, dash: bool = False) -> None:
    """ValueError, one line, for bad early-stopping settings (`dash`: named as options)."""

    def name(k: str) -> str:
        return "--" + k.replace("_", "-") if dash else k

    if not isinstance(patience, int) or isinstance(patience, bool) or patience < 1:
        raise ValueError(
            f"{name('stop_metric')} needs {name('patience')} K (generations without an "
            f"improvement), an integer >= 1, got {patience!r:.40}"
        )
    if metric not in metric_names():
        raise ValueError(
            f"{name('stop_metric')}: unknown metric {metric!r:.60} (one of: "
            f"{', '.join(metric_names())})"
        )
    if not isinstance(min_delta, (int, float)) or isinstance(min_delta, bool):
        raise ValueError(f"{name('stop_min_delta')} must be a number, got {min_delta!r:.40}")
    if not (math.isfinite(min_delta) and min_delta >= 0):
        raise ValueError(f"{name('stop_min_delta')} must be a finite number >= 0, got {min_delta}")
    if not isinstance(warmup, int) or isinstance(warmup, bool) or warmup < 0:
        raise ValueError(f"{name('stop_warmup')} must be an integer >= 0, got {warmup!r:.40}")
    if mode not in MODES:
        raise ValueError(f"{name('stop_mode')} must be max or min, got {mode!r:.40}")


def metric_stop(
    patience: int | None,
    metric: str | None,
    min_delta: float | None,
    warmup: int | None,
    mode: str | None,
    dash: bool = False,
) -> MetricStop | None:
    """The `MetricStop` of the early-stopping settings, or None when none of --stop-metric,
    --stop-min-delta, --stop-warmup, --stop-mode is given (plain --patience then watches the
    best team as it always has). ValueError, one line."""
    if metric is None and min_delta is None and warmup is None and mode is None:
        return None
    return _new(patience, metric, min_delta, warmup, mode, dash)


def _new(patience, metric, min_delta, warmup, mode, dash) -> MetricStop:
    metric = BEST if metric is None else metric
    min_delta = 0.0 if min_delta is None else min_delta
    warmup = 0 if warmup is None else warmup
    mode = "max" if mode is None else mode
    check_metric_stop(patience, metric, min_delta, warmup, mode, dash)
    return MetricStop(patience, metric, min_delta, warmup, mode)  # type: ignore[arg-type]


#: What a callback returns to stop the run: True (the reason "callback") or a reason of its own,
#: a non-empty string. Anything else (None, False, numbers, ...) lets the run go on.
def callback_verdict(value: Any) -> str | None:
    if value is True:
        return "callback"
    if isinstance(value, str) and value.strip():
        return value.strip()
    return None


class CallbackStop:
    """A user callback, called with each recorded generation's `GenerationResult`; the run
    stops after that generation when it returns True or a reason (`callback_verdict`)."""

    reason = "callback"

    def __init__(self, fn: Callable[[GenerationResult], Any]):
        self.fn = fn
        self.said: str | None = None
        self.generation: int | None = None

    def check(self, ev: Evolution, result: GenerationResult) -> str | None:
        self.said = callback_verdict(self.fn(result))
        self.generation = result.generation
        return None if self.said is None else self.reason

    def start(self, ev: Evolution, run_dir: Path | None) -> None:
        pass

    def record(self) -> dict:
        return {"callback": self.said}

    def why(self) -> str:
        extra = "" if self.said == "callback" else f": {self.said}"
        return f"the callback asked to stop after generation {self.generation}{extra}"


def stop_text(record: dict) -> str:
    """The line that says why a run stopped early, from summary.json's "stop" record
    (`session.Bounds.record`): what the API's progress prints when a bound stops a run."""
    g, reason = record.get("generation"), record.get("reason")
    if reason == "callback":
        said = record.get("callback")
        why = "the callback asked to stop" + ("" if said in (None, "callback") else f": {said}")
    elif reason == "patience" and "metric" in record:
        delta = record.get("min_delta") or 0
        why = (
            f"{record['metric']} has not improved{f' by more than {delta:g}' if delta else ''} "
            f"for {record.get('patience')} generations (best at generation "
            f"{record.get('best_generation')})"
        )
    elif reason == "patience":
        why = (
            f"the best team (generation {record.get('best_generation')}) has not improved for "
            f"{record.get('patience')} generations"
        )
    else:
        why = f"max_time reached ({record.get('elapsed_seconds')}s of {record.get('max_time_seconds')}s)"
    from .stop_lines import generations_done  # a count, and the numbers from 0

    done = generations_done(g) if isinstance(g, int) else f"{g} generations"
    return f"Stopped after {done}: {why}"
