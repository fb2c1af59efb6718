"""The application's record of a run, which the algorithm neither keeps nor reads: the run's best
team so far (`records.step` writes it after each generation, `best_team.update` decides it;
reporters, `--patience`, `--keep-checkpoints` and the API read it). One `RunRecord` is held
beside each `Evolution` while the Evolution lives (`app_record(ev)`), so that any Evolution, one the
application built or one a caller made and handed to `session.run`, has one. A checkpoint saves
it beside the algorithm's state dict, in the same file and the same atomic write, as its "app"
table (`checkpoints.save_checkpoint`); `restore` gives a resumed or branched Evolution the record
of the checkpoint it was built from."""

from __future__ import annotations

import weakref
from dataclasses import dataclass

from ..coevo.evolve import Evolution

#: The checkpoint's table of the application's record (beside the algorithm's entries).
APP_KEY = "app"


@dataclass
class RunRecord:
    """What the application keeps of a run besides the algorithm's state."""

    best: dict | None = None
    """The run's best team so far (the module docstring of `best_team`); None before a
    generation finished."""

    def state_dict(self) -> dict:
        """The checkpoint's "app" table."""
        return {"best": self.best}


_RECORDS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def app_record(ev: Evolution) -> RunRecord:
    """The application's record of `ev`'s run (an empty one for a new Evolution)."""
    r = _RECORDS.get(ev)
    if r is None:
        r = _RECORDS[ev] = RunRecord()
    return r


def set_app_record(ev: Evolution, r: RunRecord) -> None:
    """`r` as the application's record of `ev`'s run (a run interrupted between a generation and
    its records goes back to the record of its last recorded state, `session.run`)."""
    _RECORDS[ev] = r


def restore(ev: Evolution, d: dict) -> Evolution:
    """`ev`, built from the checkpoint `d` (as `checkpoint_read.read_checkpoint` returns it: its
    record in the "app" table, an older file's moved there), with the checkpoint's record."""
    set_app_record(ev, RunRecord(best=d[APP_KEY]["best"]))
    return ev
