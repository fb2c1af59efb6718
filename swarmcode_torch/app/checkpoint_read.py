"""A checkpoint file read back: unpickled without running code, its entries' types and its plain
records (generation, history, best team) checked against each other. `checkpoints` loads,
resumes and branches from what it returns.

A checkpoint holds the algorithm's state dict (`coevo.run_state.state_dict`) and, beside it, the
application's record of the run (`run_record.RunRecord`) as its "app" table: {"best": the run's
best team}. A checkpoint written before the record moved out of the algorithm's state holds
"best" among the algorithm's entries; `read_checkpoint` moves it into "app", so that every
reader sees one layout."""

from __future__ import annotations

import os
import pickle
import stat
from pathlib import Path

import torch

from .files import RunError, open_nofollow
from .run_record import APP_KEY

#: What a checkpoint may hold at the top level, and the type of each entry.
_CHECKPOINT_KEYS = {
    "version": int,
    "config": dict,
    "generation": int,
    "genome": dict,
    "species_hint": torch.Tensor,
    "proto": (dict, type(None)),
    "proto_ids": torch.Tensor,
    "next_species_id": int,
    "fitness": torch.Tensor,
    "has_fitness": torch.Tensor,
    "rng_state": torch.Tensor,
    "history": list,
}

#: What the application's "app" table holds, and the type of each entry.
_APP_KEYS = {"best": (dict, type(None))}


def _app_record(d: dict, path: Path) -> str:
    """Checks the application's record of checkpoint `d` (read from `path`): its "app" table,
    or an older checkpoint's "best" among the algorithm's entries, moved into "app" (RunError,
    one line, for a missing or mistyped entry); where the record's best team lies in the file
    ("app.best" or "best"), for the messages of `check_records`."""
    if APP_KEY in d:
        app, where = d[APP_KEY], f"{APP_KEY}."
        if not isinstance(app, dict):
            raise RunError(
                f"{path} is damaged: {APP_KEY!r} has the wrong type ({type(app).__name__})"
            )
    elif "best" in d:  # written before the record moved out of the algorithm's state
        app, where = {"best": d.pop("best")}, ""
        d[APP_KEY] = app
    else:
        raise RunError(f"{path} is not a complete checkpoint (no {APP_KEY!r})")
    for key, kind in _APP_KEYS.items():
        name = where + key
        if key not in app:
            raise RunError(f"{path} is not a complete checkpoint (no {name!r})")
        if not isinstance(app[key], kind):
            raise RunError(
                f"{path} is damaged: {name!r} has the wrong type ({type(app[key]).__name__})"
            )
    return f"{where}best"


def read_checkpoint(path: Path) -> dict:
    """The contents of a checkpoint file, unpickled with `torch.load(weights_only=True)`: only
    tensors, plain containers, numbers and strings are rebuilt, so no code in the file can run.
    RunError for a file that would call anything on loading, a damaged file, or one that is not a
    swarmcode-torch checkpoint."""
    path = Path(path)
    try:
        # never through a link; O_NONBLOCK: a FIFO planted there is refused, not waited on
        fd = open_nofollow(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with os.fdopen(fd, "rb") as f:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                raise RunError(
                    f"{path} is not a regular file (a FIFO, a device, a folder); a "
                    "checkpoint is a file torch.save wrote"
                )
            os.set_blocking(fd, True)
            d = torch.load(f, map_location="cpu", weights_only=True)
    except RunError:
        raise
    except pickle.UnpicklingError as e:
        if "weights only load failed" in str(e).lower() or "unsupported global" in str(e).lower():
            raise RunError(
                f"{path} was refused: loading it would run code (only tensors, "
                "numbers, strings and plain containers are allowed)"
            ) from None
        raise RunError(f"{path} is corrupt or not a checkpoint (UnpicklingError)") from None
    except OSError as e:
        raise RunError(f"{path} cannot be read ({e.strerror or type(e).__name__})") from None
    except Exception as e:  # noqa: BLE001 - any other failure means a damaged file
        raise RunError(f"{path} is corrupt or not a checkpoint ({type(e).__name__})") from None
    if not isinstance(d, dict) or "version" not in d:
        raise RunError(f"{path} is not a swarmcode-torch checkpoint")
    for key, kind in _CHECKPOINT_KEYS.items():
        if key not in d:
            raise RunError(f"{path} is not a complete checkpoint (no {key!r})")
        if not isinstance(d[key], kind) or isinstance(d[key], bool) and kind is int:
            raise RunError(
                f"{path} is damaged: {key!r} has the wrong type ({type(d[key]).__name__})"
            )
    check_records(d, path, _app_record(d, path))
    return d


def _integer(v, low: int = 0) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= low


def _species_id(k) -> bool:
    """A species id as a history record keys it: an integer >= 0, or its decimal text."""
    return (_integer(k) and k < 2**63) or (
        isinstance(k, str) and 0 < len(k) < 19 and k.isascii() and k.isdigit()
    )


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def check_records(d: dict, path: Path, best_at: str = "app.best") -> None:
    """RunError, one line naming `path` and the entry, unless the plain records of a checkpoint
    (its types checked) fit together: `generation` no more than the generations of the config
    it holds, one `history` record per finished generation, in order, each with its species
    composition (`population`, `team`: species id -> count), and the application's best team
    (`d["app"]["best"]`, named `best_at` in messages; None before a generation finished) of a
    finished generation, with a number for its fitness and well-formed designs. What every
    reader of a checkpoint relies on (resume, `--from`, `dynamics`, the API's load); the
    tensors are checked against the config where a run is built from them
    (`evolve.load_state_dict`)."""
    from .summary import check_designs, finite, short

    gen = d["generation"]
    if gen < 0:
        raise RunError(f"{path}: generation must be an integer >= 0, got {short(gen)}")
    total = d["config"].get("generations")
    if _integer(total) and gen > total:
        raise RunError(
            f"{path}: generation: {short(gen)} is beyond the {short(total)} generations of "
            "the run's config (the file is damaged)"
        )
    history = d["history"]
    if len(history) != gen:
        raise RunError(
            f"{path}: history must hold one record per generation 0..{gen - 1} (it has "
            f"{len(history)} for {short(gen)} finished generations)"
        )
    for i, h in enumerate(history):
        w = f"{path}: history[{i}]"
        if not isinstance(h, dict):
            raise RunError(f"{w}: expected a record (a table), got {short(h)}")
        g = h.get("generation")
        if not _integer(g) or g != i:
            raise RunError(
                f"{w}.generation: expected {i} (one record per generation, in order), "
                f"got {short(g)}"
            )
        for key in ("population", "team"):
            if key not in h and key == "team":
                continue
            v = h.get(key)
            if not isinstance(v, dict) or not all(
                _species_id(k) and _integer(n) and n < 2**63 for k, n in v.items()
            ):
                raise RunError(
                    f"{w}.{key}: expected species id -> count (integers >= 0), got {short(v)}"
                )
    best = d[APP_KEY]["best"]
    if best is None:
        return
    w = f"{path}: {best_at}"
    g = best.get("generation")
    if not _integer(g) or g >= gen:
        raise RunError(
            f"{w}.generation: expected a finished generation (0..{gen - 1}), got {short(g)}"
        )
    if not finite(best.get("fitness")):
        raise RunError(f"{w}.fitness: expected a number, got {short(best.get('fitness'))}")
    check_designs(best.get("designs"), w)
    for key, fields in (("reeval", ("mean",)), ("run_single_trial", ("fitness", "generation"))):
        v = best.get(key)
        if v is not None and not (isinstance(v, dict) and all(finite(v.get(f)) for f in fields)):
            raise RunError(f"{w}.{key}: expected a table of numbers, got {short(v)}")
    v = best.get("single_trial_fitness")
    if v is not None and not finite(v):
        raise RunError(f"{w}.single_trial_fitness: expected a number, got {short(v)}")
