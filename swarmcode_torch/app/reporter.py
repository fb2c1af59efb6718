"""The base class of a run's reporters: what a reporter is told, and when.

A reporter is an object with three hooks, called by the run (`session.run`) in this order:

- `on_start(ev)` once, before the first generation of this process (a resumed run's
  `ev.state.generation` says where it starts);
- `on_generation(ev, result)` after every generation, with its `GenerationResult`;
- `on_stop(ev, record)` when a bound stops the run early (`--max-time`, `--patience`, a
  callback), after that generation, with summary.json's "stop" record;
- `on_end(ev)` once, after the last generation (reached or stopped at). An interrupt (Ctrl-C,
  SIGTERM) or an error ends the run without it: the run's checkpoint is kept and `resume`
  continues.

Subclass `Reporter` and override the hooks you need (the others do nothing), and pass an
instance to `swarmcode_torch.evolve(reporters=[...])` or `resume`. The built-in reporters
(metrics.csv, TensorBoard, W&B, summary.json, the checkpoint, the progress line) are
subclasses. Any object with the three methods is accepted too.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..coevo.evolve import Evolution, GenerationResult


class Reporter:
    """A run's reporter: override `on_start`, `on_generation`, `on_stop` and `on_end` as
    needed."""

    def on_start(self, ev: Evolution) -> None:
        """Before the first generation of this process."""

    def on_generation(self, ev: Evolution, result: GenerationResult) -> None:
        """After every generation, with its `GenerationResult`."""

    def on_stop(self, ev: Evolution, record: dict) -> None:
        """When a bound stops the run early, with summary.json's "stop" record."""

    def on_end(self, ev: Evolution) -> None:
        """After the last generation (reached or stopped at)."""
