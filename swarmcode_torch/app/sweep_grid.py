"""A sweep over any setting (`swarmcode-torch sweep --grid KEY=V1,V2 ...`): the grid parsed,
its points (with the budgets and seeds) as configs, the name of each point's run directory, and
the sweep's progress (run k of n, time left)."""

from __future__ import annotations

import itertools
import math
import re
import time
from dataclasses import replace
from typing import Any

from ..coevo.config import SETTING_TYPES, SwarmCoDeConfig
from .eta import Eta
from .eta import clock as duration
from .settings import API_KEYS

#: Keys a grid may not vary: --budgets and --seeds sweep those; how a run runs is no setting
#: of what it computes (a sweep resumes its runs with other values of them); one sweep runs on
#: one scenario.
NOT_IN_GRID = {
    "budget": "use --budgets",
    "seed": "use --seeds",
    "generations": "it says how long each run runs, not what it computes",
    "device": "it says where the runs compute, not what",
    "compile": "it says how the runs compute, not what",
    "cuda_graphs": "it says how the runs compute, not what",
    "scenario": "a sweep runs on one scenario (--scenario)",
    "preset": "use --preset, or --grid the settings it changes",
}


def _value(key: str, text: str) -> Any:
    kind, nullable = SETTING_TYPES[key]
    try:
        if nullable and text.lower() == "none":
            return None
        if kind is bool:
            if text.lower() not in ("true", "false"):
                raise ValueError
            return text.lower() == "true"
        v = kind(text)
        if kind is float and not math.isfinite(v):
            raise ValueError
        return v
    except ValueError:
        raise ValueError(
            f"--grid {key}: expected values of type {kind.__name__}, got {text!r}"
        ) from None


def parse_grid(pairs: list[str] | None, given: dict[str, Any] | None = None) -> dict[str, list]:
    """["KEY=V1,V2,...", ...] -> {key: [typed values]}, in the order given; ValueError, one
    line, for a malformed pair, an unknown key, one the grid may not vary (`NOT_IN_GRID`), a
    key given twice (or also by its own option: `given`, the options' values, None when not
    given), or a value listed twice or of the wrong type."""
    out: dict[str, list] = {}
    for pair in pairs or []:
        key, sep, text = pair.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or not key or not text.strip():
            raise ValueError(f"--grid expects KEY=V1,V2,..., got {pair!r}")
        if key in NOT_IN_GRID:
            raise ValueError(f"--grid {key}: {NOT_IN_GRID[key]}")
        if key in API_KEYS:
            raise ValueError(f"--grid {key}: {API_KEYS[key]}")
        if key not in SETTING_TYPES:
            keys = ", ".join(sorted(set(SETTING_TYPES) - set(NOT_IN_GRID) - set(API_KEYS)))
            raise ValueError(f"--grid: unknown key {key!r} (keys: {keys})")
        if key in out:
            raise ValueError(f"--grid {key} is given twice")
        if (given or {}).get(key) is not None:
            raise ValueError(
                f"--grid {key}: also given by --{key.replace('_', '-')}; give it one way"
            )
        vals = [_value(key, t.strip()) for t in text.split(",") if t.strip()]
        for v in vals:
            if vals.count(v) > 1:
                raise ValueError(f"--grid {key} lists {v!r} twice")
        out[key] = vals
    return out


def grid_points(grid: dict[str, list]) -> list[dict[str, Any]]:
    """Every combination of the grid's values, the first key varying slowest ([{}] for none)."""
    keys = list(grid)
    return [dict(zip(keys, combo)) for combo in itertools.product(*grid.values())]


def with_point(base: SwarmCoDeConfig, point: dict[str, Any], budget, seed) -> SwarmCoDeConfig:
    return replace(base, **point, budget=budget, seed=seed)


def _text(v: Any) -> str:
    if v is None:
        return "none"
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, float):
        return f"{v:g}"
    return re.sub(r"[^A-Za-z0-9.+-]+", "-", str(v)).strip("-") or "x"


def point_name(point: dict[str, Any]) -> str:
    """The grid point's part of its run directories' names: "delta-0.3_population-50_" ("" for
    none), followed by `sweep.run_name`'s budget and seed."""
    return "".join(f"{k}-{_text(v)}_" for k, v in point.items())


class SweepProgress:
    """The sweep's own progress, in the generations of the whole sweep: "run k of n" as each
    run starts, with the generations left and about how long they take, and the elapsed and
    remaining time as each run ends (`eta.Eta` over the sweep's generations: the seconds a
    generation has taken in this invocation so far, times the generations left; "?" before one
    has finished). Runs done before this invocation count as nothing left."""

    def __init__(self, left: list[int], clock=time.monotonic):
        self.left = list(left)  # generations each run has to run, in order
        self.total = len(left)
        self.eta = Eta(sum(self.left), now=clock)
        self.ran = 0  # generations run (or given up: a failed run) by this invocation

    def line(self, k: int, name: str) -> str:
        """The line printed as run k (0-based) starts."""
        rest = sum(self.left[k:])
        left = self.eta.left(self.eta.total - rest)
        about = "?" if math.isnan(left) else duration(left)
        return (
            f"Sweep: run {k + 1} of {self.total}: {name} ({rest} generations left in the "
            f"sweep, about {about} left)"
        )

    def finished(self, k: int) -> None:
        """Run k (0-based) ended: its generations are no longer left."""
        self.ran += self.left[k]
        self.left[k] = 0

    def times(self) -> str:
        """'elapsed 3m05s, left ~1m10s' of the whole sweep (`eta.Eta.text`)."""
        return self.eta.text(self.ran)
