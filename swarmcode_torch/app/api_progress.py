"""What the Python API shows and collects while a run goes (`api.evolve`, `api.resume`): every
generation's scalars and the user's callback (`History`), the progress line (`Progress`)."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from contextlib import contextmanager
from typing import Any

from ..coevo.evolve import Evolution, GenerationResult
from . import records
from .reporter import Reporter


class History(Reporter):
    """Reporter: collects every generation's scalars (`records.scalars`); calls a user callback
    with each generation's `GenerationResult`."""

    def __init__(self, callback: Callable[[GenerationResult], Any] | None = None):
        self.rows: list[dict] = []
        self.callback = callback

    def on_start(self, ev: Evolution) -> None:
        pass

    def on_generation(self, ev: Evolution, result: GenerationResult) -> None:
        self.rows.append(records.scalars(result))
        if self.callback is not None:
            self.callback(result)

    def on_end(self, ev: Evolution) -> None:
        pass


def interactive(stream) -> bool:
    """Whether `stream` is shown as it is written: a terminal, or a notebook's output (a Jupyter
    kernel's stream, which is no terminal but redraws a line on a carriage return)."""
    if type(stream).__module__.split(".")[0] == "ipykernel":
        return True
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


def _clock(seconds: float) -> str:
    s = int(round(seconds))
    return (
        f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"
    )


class Progress(Reporter):
    """Reporter: the progress of a run on stdout, one compact line per generation (done count,
    time left, best fitness, species, the generation's best team, seconds per generation). On a
    terminal or in a notebook the line is redrawn in place and ended when the run ends;
    elsewhere (a log) each generation prints its own line."""

    def __init__(self):
        self.stream = None
        self.inplace = False
        self.width = 0

    def on_start(self, ev: Evolution) -> None:
        self.stream = sys.stdout
        self.inplace = interactive(self.stream)
        self.start, self.first, self.width = time.monotonic(), ev.state.generation, 0

    def on_generation(self, ev: Evolution, result: GenerationResult) -> None:
        done, total = ev.state.generation, ev.cfg.generations
        ran = done - self.first
        left = (time.monotonic() - self.start) / ran * (total - done) if ran > 0 else None
        team = result.team
        line = (
            f"done {done}/{total}  left {'?' if left is None else _clock(left)}  best "
            f"{result.best['fitness']:.1f}  species {result.num_species}  team "
            f"{team['species']} sp, {team['niches']} niches, ${team['cost']:.0f}  "
            f"{result.seconds:.2f}s/gen"
        )
        if self.inplace:
            self.stream.write("\r" + line.ljust(self.width))
            self.width = max(self.width, len(line))
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def on_end(self, ev: Evolution) -> None:
        self.close()

    def on_stop(self, ev: Evolution, record: dict) -> None:
        """A bound or the callback stopped the run: a line saying why (`stopping.stop_text`)."""
        from .stopping import stop_text

        self.close()
        self.stream.write(stop_text(record) + "\n")
        self.stream.flush()

    def close(self) -> None:
        """End the line redrawn in place (at the end of a run, or when it stops)."""
        if self.inplace and self.width:
            self.stream.write("\n")
            self.stream.flush()
            self.width = 0


def progress_reporter(progress: bool | None) -> Progress | None:
    """The progress reporter of `progress`: None (the default) shows it on a terminal or in a
    notebook, True always, False never."""
    if progress is not None and not isinstance(progress, bool):
        raise TypeError(f"progress must be True, False or None, got {progress!r:.40}")
    if progress is False or (progress is None and not interactive(sys.stdout)):
        return None
    return Progress()


@contextmanager
def closing(shown: Progress | None):
    """The progress line ended however the run ends (a Ctrl-C, an error)."""
    try:
        yield
    finally:
        if shown is not None:
            shown.close()
