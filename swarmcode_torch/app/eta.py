"""Elapsed and remaining time for the plain progress lines (output to a file, a log, Slurm,
nohup): `Eta` counts from where this process started (a resumed run counts the generations it
runs, not those before) and estimates what is left from the rate so far. `parse_duration`: a
duration as --max-time and `max_time=` take it (90m, 2h, 1h30m)."""

from __future__ import annotations

import math
import re
import time


def clock(seconds: float) -> str:
    """A duration, short: '42s', '3m05s', '2h03m', '4d07h'."""
    s = max(0, int(round(seconds)))
    if s < 60:
        return f"{s}s"
    if s < 3600:
        return f"{s // 60}m{s % 60:02d}s"
    if s < 86400:
        return f"{s // 3600}h{s % 3600 // 60:02d}m"
    return f"{s // 86400}d{s % 86400 // 3600:02d}h"


class Eta:
    """Elapsed and remaining time of `total` steps (generations, runs), `start` of them done
    before this process began; `now` a clock for tests (default time.monotonic)."""

    def __init__(self, total: int, start: int = 0, now=time.monotonic):
        self.total, self.start, self.now = total, start, now
        self.t0 = now()

    def restart(self) -> None:
        """Count elapsed time from now (a run's first generation starts here)."""
        self.t0 = self.now()

    def left(self, done: int) -> float:
        """Seconds left after `done` steps at the rate so far; nan before the first step."""
        elapsed, ran = self.now() - self.t0, done - self.start
        if done >= self.total:
            return 0.0
        return elapsed / ran * (self.total - done) if ran > 0 else math.nan

    def text(self, done: int) -> str:
        """'elapsed 3m05s, left ~1m10s' after `done` steps ('left ?' before the first)."""
        left = self.left(done)
        est = "?" if math.isnan(left) else ("0s" if left == 0 else f"~{clock(left)}")
        return f"elapsed {clock(self.now() - self.t0)}, left {est}"


_DURATION = re.compile(r"(\d+(?:\.\d*)?|\.\d+)\s*([dhms]?)")
_UNIT = {"d": 86400, "h": 3600, "m": 60, "s": 1, "": 1}


def parse_duration(value: str | float | int, name: str = "max_time") -> float:
    """Seconds of a duration: a number (seconds), or text such as 3600, 90m, 2h, 1h30m, 45s,
    1.5h, 2d; ValueError, one line naming `name`, for anything else or a duration that is not
    > 0."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        seconds = float(value)
    elif isinstance(value, str):
        text = value.strip().lower()
        parts = _DURATION.findall(text)
        if (
            not text
            or "".join(n + u for n, u in parts) != text.replace(" ", "")
            or (len(parts) > 1 and any(u == "" for _, u in parts))
        ):
            raise ValueError(
                f"{name} must be a duration such as 3600 (seconds), 90m, 2h or "
                f"1h30m, got {value!r:.40}"
            )
        seconds = sum(float(n) * _UNIT[u] for n, u in parts)
    else:
        raise ValueError(
            f"{name} must be a duration such as 3600 (seconds), 90m or 2h, got {value!r:.40}"
        )
    if not (seconds > 0 and math.isfinite(seconds)):
        raise ValueError(f"{name} must be a duration > 0, got {value!r:.40}")
    return seconds
