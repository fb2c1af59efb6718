"""Fuzzing the files of a run directory (issue 39): summary.json, teams.jsonl, metrics.csv,
config.toml and checkpoint.pt of a tiny finished run are mutated at random (a value at any
depth replaced by another of any type, a field deleted, lines and rows dropped, duplicated,
reordered or garbage, cells and header cells edited, byte garbage, a checkpoint entry replaced by
another value or a tensor of another dtype or shape), and every command that reads the file
(`inspect`, `dynamics`, `replay` GIF and page, `evolve --resume`) runs on the copy. Each case
ends with exit 0 or a one-line error naming the file (no traceback), within 60 s, and the run's
files unchanged; a resume that succeeds keeps the records of the generations before its
checkpoint.

The default run is small and deterministic (derandomize=True); `pytest -m fuzz` runs the same
properties with many more random examples.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import shutil
import signal
import sys
import tempfile
from pathlib import Path

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mutationkit import MUTATIONS
from typer.testing import CliRunner

from swarmcode_torch.app.cli import app

if sys.version_info >= (3, 11):
    pass
else:  # pragma: no cover
    pass

runner = CliRunner()
QUICK = settings(
    max_examples=15,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=list(HealthCheck),
)
LONG = settings(
    max_examples=200, deadline=None, database=None, suppress_health_check=list(HealthCheck)
)
#: The seconds one command may take on a mutated run before the case counts as a hang.
HANG_S = 60
RUN = [
    "--scenario",
    "one-niche",
    "--population",
    "6",
    "--swarm-size",
    "3",
    "--trials",
    "1",
    "--ticks",
    "6",
    "--generations",
    "3",
    "--checkpoint-every",
    "1",
    "--render-every",
    "0",
    "--no-compile",
    "--device",
    "cpu",
]
#: The commands a case runs: (name, arguments after the run directory's place is filled).
COMMANDS = {
    "inspect": ["inspect", "{run}"],
    "dynamics": ["dynamics", "{run}"],
    "replay": ["replay", "{run}", "--ticks", "3", "--out", "{out}/team.gif"],
    "replay-html": ["replay", "{run}", "--ticks", "3", "--html", "--out", "{out}/team.html"],
    "replay-generation": [
        "replay",
        "{run}",
        "--generation",
        "1",
        "--ticks",
        "3",
        "--out",
        "{out}/g1.gif",
    ],
    "resume": ["evolve", "--resume", "{run}", "--generations", "4", "--render-every", "0"],
}
#: The commands that read each file (a resume reads them all).
READERS = {
    "summary.json": ["inspect", "replay", "replay-html", "resume"],
    "teams.jsonl": ["inspect", "replay-generation", "dynamics", "resume"],
    "metrics.csv": ["inspect", "dynamics", "resume"],
    "config.toml": ["inspect", "dynamics", "replay", "replay-html", "resume"],
    "checkpoint.pt": ["inspect", "dynamics", "replay", "resume"],
}


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    logdir = tmp_path_factory.mktemp("fuzzfiles")
    r = runner.invoke(app, ["evolve", *RUN, "--logdir", str(logdir)])
    assert r.exit_code == 0, r.output
    (run,) = list(logdir.iterdir())
    return run


CASES = [(f, c) for f, cs in READERS.items() for c in cs]


# ------------------------------------------------------------------ the property
def _files(run: Path) -> dict[str, bytes]:
    return {
        str(f.relative_to(run)): f.read_bytes()
        for f in sorted(run.rglob("*"))
        if f.is_file() and not f.is_symlink()
    }


@contextlib.contextmanager
def _time_guard(seconds: int):
    """A TimeoutError in the command after `seconds` (a hang is a failed case, not a stuck
    test run)."""

    def stop(signum, frame):
        raise TimeoutError(f"no answer within {seconds} s")

    old = signal.signal(signal.SIGALRM, stop)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def one_line_or_success(result, name: str) -> None:
    """exit 0, or a one-line error naming the file `name`; never a traceback."""
    assert "Traceback" not in result.output, result.output[-3000:]
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(
        result.exception
    )
    if result.exit_code != 0:
        lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1, result.output[-3000:]
        assert lines[0].startswith("Error: "), result.output[-3000:]
        assert name in lines[0], lines[0]


def _kept_teams(before: bytes, generation: int) -> bytes:
    """The lines of teams.jsonl a resume from a checkpoint of `generation` keeps: every complete
    line but the records of generations it computes again."""
    keep = []
    for line in before.splitlines(keepends=True):
        if not line.endswith(b"\n"):
            continue  # a cut-off last line: set aside in teams.jsonl.partial
        try:
            rec = json.loads(line)
        except (ValueError, RecursionError):
            rec = None
        g = rec.get("generation") if isinstance(rec, dict) else None
        if not (isinstance(g, int) and not isinstance(g, bool) and g >= generation):
            keep.append(line)
    return b"".join(keep)


def _metric_rows(data: bytes, below: int) -> list[dict]:
    rows = csv.DictReader(io.StringIO(data.decode(), newline=""))
    return [r for r in rows if int(r["generation"]) < below]


def _check_resume_kept_records(before: dict, after: dict, generation: int) -> None:
    for name in ("scenario.toml", "hardware.toml"):
        assert after.get(name) == before.get(name), name
    if "teams.jsonl" in before:
        assert after["teams.jsonl"].startswith(_kept_teams(before["teams.jsonl"], generation))
    if "metrics.csv" in before:
        old = _metric_rows(before["metrics.csv"], generation)
        new = _metric_rows(after["metrics.csv"], generation)
        assert [{k: r.get(k) for k in o} for o, r in zip(old, new)] == old
        assert len(new) == len(old)


def _case(finished_run: Path, name: str, command: str, mutate) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        run, out = Path(tmp) / "run", Path(tmp) / "out"
        shutil.copytree(finished_run, run)
        out.mkdir()
        path = run / name
        path.write_bytes(mutate(path.read_bytes()))
        before = _files(run)
        args = [a.format(run=run, out=out) for a in COMMANDS[command]]
        with _time_guard(HANG_S):
            result = runner.invoke(app, args)
        one_line_or_success(result, name)
        after = _files(run)
        if command == "resume" and result.exit_code == 0:
            generation = torch.load(io.BytesIO(before["checkpoint.pt"]), weights_only=True)[
                "generation"
            ]
            _check_resume_kept_records(before, after, generation)
        else:
            assert after == before, sorted(k for k in after if after.get(k) != before.get(k))


@pytest.mark.parametrize("name,command", CASES)
@QUICK
@given(data=st.data())
def test_fuzz_run_files(finished_run, name, command, data):
    _case(finished_run, name, command, lambda b: MUTATIONS[name](data.draw, b))


@pytest.mark.fuzz
@pytest.mark.parametrize("name,command", CASES)
@LONG
@given(data=st.data())
def test_fuzz_run_files_long(finished_run, name, command, data):
    _case(finished_run, name, command, lambda b: MUTATIONS[name](data.draw, b))


# ------------------------------------------------------------------ what the fuzzing found
def _json_edit(edit):
    def mutate(data: bytes) -> bytes:
        d = json.loads(data)
        edit(d)
        return json.dumps(d).encode()

    return mutate


def _design(key, value):
    def edit(d):
        d["designs"][0][key] = value

    return _json_edit(edit)


def _checkpoint_edit(edit):
    def mutate(data: bytes) -> bytes:
        d = torch.load(io.BytesIO(data), weights_only=True)
        edit(d)
        buf = io.BytesIO()
        torch.save(d, buf)
        return buf.getvalue()

    return mutate


def _teams_huge_line(data: bytes) -> bytes:
    return data + b'{"generation": 1' + b"0" * 5000 + b"}\n"


FOUND = [
    # a design's selectivity was not checked: float() of a list in the replay
    ("summary.json", "replay", _design("selectivity", {"x": [0]}), "designs[0].selectivity"),
    # a tier compared with `in (1, 2, 3)`: a tensor's truth value in dynamics and resume
    (
        "checkpoint.pt",
        "dynamics",
        _checkpoint_edit(
            lambda d: d["app"]["best"]["designs"][0].__setitem__("battery_tier", torch.tensor([]))
        ),
        "app.best: designs[0].battery_tier",
    ),
    # an integer of 5,000 digits: ValueError from json.loads and from every repr of it
    ("summary.json", "inspect", lambda b: b"1" + b"0" * 5000, "more than 4300 digits"),
    ("teams.jsonl", "replay-generation", _teams_huge_line, "more than 4300 digits"),
    (
        "checkpoint.pt",
        "dynamics",
        _checkpoint_edit(lambda d: d["app"]["best"]["designs"][0].__setitem__("radius", 10**400)),
        "app.best: designs[0].radius",
    ),
    # an integer too large for a float: OverflowError from math.isfinite
    ("summary.json", "inspect", _design("radius", 10**400), "designs[0].radius"),
    ("summary.json", "replay-html", _design("cost", -(10**400)), "designs[0].cost"),
    (
        "summary.json",
        "inspect",
        _json_edit(lambda d: d.update(best_fitness=10**400)),
        "best_fitness",
    ),
    # checkpoint records that passed its checks and broke the resume: a best fitness too
    # large for a float (OverflowError) and a population count beyond int64 (TypeError)
    (
        "checkpoint.pt",
        "resume",
        _checkpoint_edit(lambda d: d["app"]["best"].__setitem__("fitness", 10**400)),
        "app.best.fitness",
    ),
    (
        "checkpoint.pt",
        "resume",
        _checkpoint_edit(lambda d: d["history"][1]["population"].__setitem__(3, 10**400)),
        "history[1].population",
    ),
    # a best fitness of NaN was resumed from (no later team compares above it)
    (
        "checkpoint.pt",
        "resume",
        _checkpoint_edit(lambda d: d["app"]["best"].__setitem__("fitness", math.nan)),
        "app.best.fitness",
    ),
]


@pytest.mark.parametrize(
    "name,command,mutate,needle",
    FOUND,
    ids=[
        "selectivity-table",
        "tier-empty-tensor",
        "summary-5000-digits",
        "teams-5000-digits",
        "checkpoint-radius-10e400",
        "radius-10e400",
        "cost-minus-10e400",
        "best-fitness-10e400",
        "checkpoint-best-fitness-10e400",
        "checkpoint-population-count-10e400",
        "checkpoint-best-fitness-nan",
    ],
)
def test_what_the_fuzzing_found_is_one_line(finished_run, name, command, mutate, needle):
    with tempfile.TemporaryDirectory() as tmp:
        run, out = Path(tmp) / "run", Path(tmp) / "out"
        shutil.copytree(finished_run, run)
        out.mkdir()
        (run / name).write_bytes(mutate((run / name).read_bytes()))
        before = _files(run)
        with _time_guard(HANG_S):
            result = runner.invoke(app, [a.format(run=run, out=out) for a in COMMANDS[command]])
        assert result.exit_code == 2, result.output[-3000:]
        one_line_or_success(result, name)
        assert needle in result.stderr, result.stderr
        assert _files(run) == before
