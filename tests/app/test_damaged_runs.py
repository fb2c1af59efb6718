"""Damaged run files (issue 39, item 8): a checkpoint whose records do not fit together (a
generation of 10^6 or beyond the run's generations, a best team with text for its fitness, an
empty one or one of garbage designs, history records that are not records, lack their
population or are out of order), summary.json designs whose capability is not a list of the
scenario's package classes or whose tree is nested 4,096 levels deep, and a snapshot that is a
FIFO. Each is a one-line error naming the file and the field, exit 2, no traceback, no hang and
no file of the run changed, in every command that reads it (resume, --from, dynamics;
inspect, replay); a deep tree, which is a valid program, is shown. docs/RELIABILITY.md lists
the promise with these tests."""

from __future__ import annotations

import io
import json
import os
import threading
import time
from pathlib import Path

import pytest
import torch
from test_hostile import RFAST, TINY, invoke, one_line_error


@pytest.fixture(scope="module")
def run_with_snapshots(tmp_path_factory) -> Path:
    """A finished run of 2 generations with a snapshot of each (snapshots/generation-00000G.pt)."""
    logdir = tmp_path_factory.mktemp("runs")
    r = invoke("evolve", *TINY, "--generations", 2, "--snapshot-every", 1, "--logdir", logdir)
    assert r.exit_code == 0, r.output
    (run,) = list(logdir.iterdir())
    assert sorted(p.name for p in (run / "snapshots").iterdir()) == [
        "generation-000001.pt",
        "generation-000002.pt",
    ]
    return run


def _copy(run: Path, to: Path) -> Path:
    for f in run.rglob("*"):
        if f.is_file():
            (to / f.relative_to(run)).parent.mkdir(parents=True, exist_ok=True)
            (to / f.relative_to(run)).write_bytes(f.read_bytes())
    return to


def _files(run: Path) -> dict[str, bytes]:
    """Every file of a run directory (snapshots included) and its bytes."""
    return {
        str(f.relative_to(run)): f.read_bytes()
        for f in sorted(run.rglob("*"))
        if f.is_file() and not f.is_symlink()
    }


def _edit(path: Path, edit) -> None:
    d = torch.load(path, weights_only=True)
    edit(d)
    buf = io.BytesIO()
    torch.save(d, buf)
    path.write_bytes(buf.getvalue())


def _beyond(d) -> None:  # a generation past the run's 2, with a record for each
    d["history"] += [dict(d["history"][-1], generation=g) for g in range(len(d["history"]), 7)]
    d["generation"] = 7


def _best(key, value):
    def edit(d):
        d["app"]["best"][key] = value

    return edit


def _set(key, value):
    def edit(d):
        d[key] = value

    return edit


def _no_population(d) -> None:
    for h in d["history"]:
        del h["population"]


@pytest.mark.parametrize(
    "edit,needle",
    [
        (_set("generation", 10**6), "generation: 1000000 is beyond the 2 generations"),
        (_beyond, "generation: 7 is beyond the 2 generations"),
        (_best("fitness", "high"), "app.best.fitness: expected a number, got 'high'"),
        (_set("app", {"best": {}}), "app.best.generation: expected a finished generation"),
        (_best("designs", [{"x": 1}, 5]), "app.best: designs[0]: missing 'count'"),
        (_best("designs", "lots"), "app.best: designs: expected a non-empty list"),
        (
            lambda d: d.__setitem__("history", list(range(len(d["history"])))),
            "history[0]: expected a record",
        ),
        (_no_population, "history[0].population: expected species id -> count"),
        (
            lambda d: d["history"].reverse(),
            "history[0].generation: expected 0 (one record per generation, in order), got 1",
        ),
    ],
    ids=[
        "generation-1e6",
        "generation-beyond-the-run",
        "best-fitness-text",
        "best-empty",
        "best-garbage-designs",
        "best-designs-text",
        "history-ints",
        "history-no-population",
        "history-out-of-order",
    ],
)
def test_a_damaged_checkpoint_is_one_line_in_every_reader(
    run_with_snapshots, tmp_path, edit, needle
):
    run = _copy(run_with_snapshots, tmp_path / "run")
    for path in (run / "checkpoint.pt", run / "snapshots" / "generation-000002.pt"):
        _edit(path, edit)
    before = _files(run)
    ck, snap = str(run / "checkpoint.pt"), str(run / "snapshots" / "generation-000002.pt")
    one_line_error(invoke("evolve", "--resume", run, "--generations", 4, *RFAST), ck, needle)
    one_line_error(invoke("dynamics", run), ck, needle)
    branch = tmp_path / "branch"
    one_line_error(
        invoke("evolve", "--from", f"{run}@2", "--generations", 4, "--logdir", branch, *RFAST),
        snap,
        needle,
    )
    assert not branch.exists() or not any(branch.iterdir())  # no run directory made
    assert _files(run) == before


def _capability(value):
    def edit(s):
        s["designs"][0]["capability"] = value

    return edit


@pytest.mark.parametrize(
    "edit,needle",
    [
        (_capability(3), "designs[0].capability: expected a list of package class indices"),
        (_capability(None), "designs[0].capability: expected a list of package class indices"),
        (_capability([99]), "designs[0].capability: package class 99 does not exist"),
        (_capability([-1]), "designs[0].capability: expected a list of package class indices"),
        (_capability("lifts all"), "designs[0].capability: expected a list of package class"),
        (_capability([0] * 10**6), "got a list of 1000000 entries"),
    ],
    ids=["int", "null", "class-99", "minus-1", "text", "million-entries"],
)
def test_a_damaged_design_capability_is_one_line_in_inspect_and_replay(
    run_with_snapshots, tmp_path, edit, needle
):
    run = _copy(run_with_snapshots, tmp_path / "run")
    s = json.loads((run / "summary.json").read_text())
    edit(s)
    (run / "summary.json").write_text(json.dumps(s))
    before = _files(run)
    t = time.monotonic()
    one_line_error(invoke("inspect", run), "summary.json", needle)
    one_line_error(invoke("replay", run, "--ticks", 3, "--out", tmp_path / "t.gif"), needle)
    one_line_error(
        invoke("replay", run, "--ticks", 3, "--html", "--out", tmp_path / "t.html"), needle
    )
    assert time.monotonic() - t < 60
    assert _files(run) == before
    assert not (tmp_path / "t.gif").exists() and not (tmp_path / "t.html").exists()


def test_a_tree_nested_4096_levels_deep_is_shown_not_a_recursion_error(
    run_with_snapshots, tmp_path
):
    run = _copy(run_with_snapshots, tmp_path / "run")
    s = json.loads((run / "summary.json").read_text())
    s["designs"][0]["bt"] = [0] * 4096  # SEQ in every slot: 4096 nested blocks, a valid program
    (run / "summary.json").write_text(json.dumps(s))
    before = _files(run)
    t = time.monotonic()
    r = invoke("inspect", run)
    assert r.exit_code == 0 and "Traceback" not in r.output, r.output[-2000:]
    assert "\n" + "  " * 4096 + "SEQ\n" in r.output  # the deepest node, at its depth
    r = invoke("replay", run, "--ticks", 3, "--html", "--out", tmp_path / "t.html")
    assert r.exit_code == 0 and "Traceback" not in r.output, r.output[-2000:]
    assert time.monotonic() - t < 60
    assert _files(run) == before


def _open_for_a_moment_later(fifo: Path, after: float) -> None:
    """After `after` seconds, open the FIFO for writing and close it: a reader blocked on it
    (the bug) gets end-of-file and the test goes on instead of hanging."""

    def run():
        time.sleep(after)
        try:
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        except OSError:  # no reader waits: nothing to unblock
            pass

    threading.Thread(target=run, daemon=True).start()


def test_a_snapshot_that_is_a_fifo_is_refused_at_once(run_with_snapshots, tmp_path):
    run = _copy(run_with_snapshots, tmp_path / "run")
    snap = run / "snapshots" / "generation-000001.pt"
    snap.unlink()
    os.mkfifo(snap)
    before = _files(run)
    _open_for_a_moment_later(snap, 15)
    t = time.monotonic()
    r = invoke("evolve", "--from", f"{run}@1", "--generations", 4, "--logdir", tmp_path / "b")
    one_line_error(r, str(snap), "is not a regular file")
    assert time.monotonic() - t < 10
    assert _files(run) == before and snap.is_fifo()
    assert not (tmp_path / "b").exists() or not any((tmp_path / "b").iterdir())
