"""Interrupts at every write step: a run stopped by Ctrl-C (SIGINT, delivered for real with
`signal.raise_signal`), by SIGTERM or killed outright (an exception nothing catches, as SIGKILL
leaves the files) after its N-th write step, then resumed, writes the same files as a run made
straight through (teams.jsonl and metrics.csv rows, summary.json but for timings, the final
checkpoint). The write steps are `runs.interrupt_point`: after each file written or appended to
and after each generation computed. docs/RELIABILITY.md, "Interrupts"."""

from __future__ import annotations

import csv
import io
import json
import re
import signal
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from swarmcode_torch.app import files as files_module
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.runs import load_checkpoint

runner = CliRunner()
GENERATIONS = 4
BASE = [
    "--scenario",
    "one-niche",
    "--population",
    "6",
    "--swarm-size",
    "4",
    "--trials",
    "1",
    "--ticks",
    "8",
    "--render-every",
    "0",
    "--figure-every",
    "1000",
    "--no-compile",
    "--device",
    "cpu",
]
RFAST = ["--render-every", "0", "--figure-every", "1000", "--device", "cpu"]


@pytest.fixture(autouse=True)
def _ctrl_c_is_delivered():
    """These tests deliver Ctrl-C for real. A process started with SIGINT ignored (a background
    job of a non-interactive shell) has no KeyboardInterrupt handler, so install Python's for
    each test and put back what was there."""
    old = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


class Killed(BaseException):
    """What SIGKILL leaves: nothing after the kill point runs (no handler, no checkpoint)."""


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


class StopAt:
    """runs.interrupt_point that stops the run at its `nth` call: 'int' sends SIGINT, 'term'
    SIGTERM (both for real, to this process), 'kill' raises `Killed`. `count` counts the calls."""

    def __init__(self, nth: int, how: str):
        self.nth, self.how, self.count, self.fired = nth, how, 0, False

    def __call__(self, what: str) -> None:
        self.count += 1
        if self.count != self.nth or self.fired:
            return
        self.fired = True
        if self.how == "kill":
            raise Killed(what)
        signal.raise_signal(signal.SIGINT if self.how == "int" else signal.SIGTERM)


def _named_checkpoint(line: str) -> int:
    """The last finished generation a stop message names (-1: before generation 0)."""
    if "checkpoint before generation 0 (no generation finished yet) is in" in line:
        return -1
    m = re.search(
        r"checkpoint after generation (\d+) \(generations? 0(?:-(\d+))? finished\) is in", line
    )
    assert m, line
    assert int(m.group(2) or 0) == int(m.group(1)), line
    return int(m.group(1))


def _rows(path: Path) -> list[dict]:
    rows = list(csv.DictReader(io.StringIO(path.read_text())))
    return [{k: v for k, v in r.items() if not k.startswith("perf/")} for r in rows]


def _summary(path: Path) -> dict:
    s = json.loads(path.read_text())
    s["last_generation"] = {
        k: v for k, v in s["last_generation"].items() if not k.startswith("perf/")
    }
    return s


def _same_run(a: Path, b: Path) -> None:
    assert (a / "teams.jsonl").read_bytes() == (b / "teams.jsonl").read_bytes()
    assert _rows(a / "metrics.csv") == _rows(b / "metrics.csv")
    assert _summary(a / "summary.json") == _summary(b / "summary.json")
    ca, cb = load_checkpoint(a), load_checkpoint(b)
    assert ca["generation"] == cb["generation"] == GENERATIONS
    assert torch.equal(ca["rng_state"], cb["rng_state"]) and ca["history"] == cb["history"]
    assert ca["app"] == cb["app"]
    for k in ca["genome"]:
        assert torch.equal(ca["genome"][k], cb["genome"][k]), k
    for k in ("fitness", "has_fitness", "species_hint", "proto_ids"):
        assert torch.equal(ca[k], cb[k]), k


@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    """The run made straight through, per (seed, checkpoint_every), and its count of write
    steps."""
    made = {}

    def get(seed: int, every: int):
        if (seed, every) not in made:
            logdir = tmp_path_factory.mktemp(f"straight{seed}_{every}")
            counter = StopAt(0, "int")
            mp = pytest.MonkeyPatch()
            mp.setattr(files_module, "interrupt_point", counter)
            try:
                r = invoke(
                    "evolve",
                    *BASE,
                    "--seed",
                    seed,
                    "--generations",
                    GENERATIONS,
                    "--checkpoint-every",
                    every,
                    "--logdir",
                    logdir,
                )
            finally:
                mp.undo()
            assert r.exit_code == 0, r.output
            (run,) = list(logdir.iterdir())
            made[seed, every] = run, counter.count
        return made[seed, every]

    return get


def _interrupted_then_resumed(
    tmp_path: Path, straight, seed: int, every: int, nth: int, how: str
) -> None:
    ref, steps = straight(seed, every)
    assert nth <= steps
    stop = StopAt(nth, how)
    mp = pytest.MonkeyPatch()
    mp.setattr(files_module, "interrupt_point", stop)
    r = None
    try:
        r = invoke(
            "evolve",
            *BASE,
            "--seed",
            seed,
            "--generations",
            GENERATIONS,
            "--checkpoint-every",
            every,
            "--logdir",
            tmp_path,
        )
    except Killed:
        pass  # the process is gone: nothing more ran
    finally:
        mp.undo()
    assert stop.fired
    (run,) = list(tmp_path.iterdir())
    if how == "kill":
        assert r is None or isinstance(r.exception, Killed), r.output
    elif r.exit_code == 0:
        # the signal arrived after the last checkpoint, in the end-of-run work: the run is whole
        pass
    else:
        assert r.exit_code == (130 if how == "int" else 143), r.output
        assert "Traceback" not in r.output
        line = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert len(line) == 1, r.output
        if (run / "checkpoint.pt").exists():
            held = load_checkpoint(run)["generation"]
            assert _named_checkpoint(line[0]) == held - 1, r.output
            if held:  # the message numbers generations as summary.json does
                assert json.loads((run / "summary.json").read_text())["generation"] == held - 1
        else:
            assert "no checkpoint was written yet" in line[0], r.output
    if not (run / "checkpoint.pt").exists():  # stopped before generation 0 was saved
        r = invoke(
            "evolve",
            *BASE,
            "--seed",
            seed,
            "--generations",
            GENERATIONS,
            "--checkpoint-every",
            every,
            "--logdir",
            tmp_path / "again",
        )
        assert r.exit_code == 0, r.output
        (run,) = list((tmp_path / "again").iterdir())
    else:
        teams = (
            [json.loads(x)["generation"] for x in (run / "teams.jsonl").read_text().splitlines()]
            if (run / "teams.jsonl").exists()
            else []
        )
        held = load_checkpoint(run)["generation"]
        assert teams[:held] == list(range(held))  # every checkpointed generation recorded
        r = invoke("evolve", "--resume", run, *RFAST)
        assert r.exit_code == 0, r.output
    _same_run(ref, run)


# the default suite: a few points of each kind; the sweep below covers every point
@pytest.mark.parametrize(
    "how,seed,every,nth",
    [
        ("int", 0, 2, 1),
        ("int", 0, 2, 4),
        ("int", 0, 2, 7),
        ("term", 0, 2, 9),
        ("kill", 0, 2, 3),
        ("kill", 0, 2, 6),
        ("int", 1, 3, 12),
        ("kill", 1, 3, 13),
    ],
)
def test_a_run_stopped_after_a_write_step_resumes_to_the_straight_run(
    tmp_path, straight, how, seed, every, nth
):
    _interrupted_then_resumed(tmp_path, straight, seed, every, nth, how)


def _sweep_points() -> list[tuple[str, int, int, int]]:
    """Every write step of three seeded runs (checkpoints every 2, 3 and 1 generations; 23, 23
    and 25 steps), each stopped by Ctrl-C, SIGTERM or a kill in turn: 71 points."""
    points = []
    for seed, every in ((0, 2), (1, 3), (2, 1)):
        for nth in range(1, 26):
            points.append((("int", "term", "kill")[(nth + seed) % 3], seed, every, nth))
    return points


@pytest.mark.slow
@pytest.mark.parametrize("how,seed,every,nth", _sweep_points())
def test_interrupt_sweep_every_write_step(tmp_path, straight, how, seed, every, nth):
    ref, steps = straight(seed, every)
    if nth > steps:
        pytest.skip(f"the run has {steps} write steps")
    _interrupted_then_resumed(tmp_path, straight, seed, every, nth, how)


@pytest.mark.parametrize("how", ["int", "term"])
def test_a_signal_in_the_end_of_run_work_names_the_checkpoint_the_file_holds(tmp_path, how):
    """SIGTERM or Ctrl-C while the end-of-run reporters draw (the last figure, hparams): the
    last generation's checkpoint was written with its records, and the message says so."""
    from swarmcode_torch.app.reporting import TensorBoardReporter

    real = TensorBoardReporter.on_end

    def on_end(self, ev):
        signal.raise_signal(signal.SIGINT if how == "int" else signal.SIGTERM)
        return real(self, ev)

    mp = pytest.MonkeyPatch()
    mp.setattr(TensorBoardReporter, "on_end", on_end)
    try:
        r = invoke(
            "evolve",
            *BASE,
            "--seed",
            0,
            "--generations",
            3,
            "--checkpoint-every",
            2,
            "--logdir",
            tmp_path,
        )
    finally:
        mp.undo()
    (run,) = list(tmp_path.iterdir())
    assert r.exit_code == (130 if how == "int" else 143), r.output
    assert load_checkpoint(run)["generation"] == 3
    assert "checkpoint after generation 2 (generations 0-2 finished) is in" in r.stderr, r.output
    assert json.loads((run / "summary.json").read_text())["generation"] == 2
    teams = [json.loads(x)["generation"] for x in (run / "teams.jsonl").read_text().splitlines()]
    assert teams == [0, 1, 2]


def test_deferred_signals_hold_ctrl_c_until_the_step_is_done():
    from swarmcode_torch.app.runs import deferred_signals

    done = []
    with pytest.raises(KeyboardInterrupt):
        with deferred_signals() as held:
            signal.raise_signal(signal.SIGINT)
            done.append("records")  # the step goes on
            done.append("checkpoint")
    assert done == ["records", "checkpoint"] and held == [signal.SIGINT]
    with deferred_signals(deliver=False) as held:  # a stop under way: a second one is dropped
        signal.raise_signal(signal.SIGINT)
    assert held == [signal.SIGINT]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


@pytest.mark.parametrize("how,nth", [("int", 7), ("term", 4), ("int", 6)])
def test_the_stop_message_names_the_generation_summary_json_holds(tmp_path, how, nth):
    # Ctrl-C or SIGTERM at a fixed write step: the message numbers the checkpoint's last
    # generation as summary.json (and teams.jsonl) do, from 0
    stop = StopAt(nth, how)
    mp = pytest.MonkeyPatch()
    mp.setattr(files_module, "interrupt_point", stop)
    try:
        r = invoke(
            "evolve",
            *BASE,
            "--seed",
            0,
            "--generations",
            GENERATIONS,
            "--checkpoint-every",
            1,
            "--logdir",
            tmp_path,
        )
    finally:
        mp.undo()
    assert stop.fired and r.exit_code == (130 if how == "int" else 143), r.output
    (run,) = list(tmp_path.iterdir())
    held = load_checkpoint(run)["generation"]
    named = _named_checkpoint(r.stderr)
    assert named == held - 1
    summary = run / "summary.json"
    if held == 0:
        assert not summary.exists()
    else:
        last = json.loads(summary.read_text())["generation"]
        assert named == last >= 0
        teams = [
            json.loads(x)["generation"] for x in (run / "teams.jsonl").read_text().splitlines()
        ]
        assert teams[-1] == last


def _cli_with_ctrl_c(*args: str, logdir: Path):
    """The command line in a subprocess whose SIGINT is Python's (a background job inherits SIGINT
    ignored: the child resets it to the default, so Python installs its handler at start-up)."""
    import subprocess
    import sys

    return subprocess.Popen(
        [sys.executable, "-m", "swarmcode_torch.app.cli", *args, "--logdir", str(logdir)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )


@pytest.mark.subprocess
@pytest.mark.parametrize("how", ["int", "term"])
def test_a_second_signal_during_the_stop_or_the_exit_never_kills_the_process(tmp_path, how):
    """SIGINT (or SIGTERM) twice, 0.05 s apart, then again every 0.05 s until the process is
    gone: the stop and the interpreter's exit are hit wherever they stand; the exit status is
    still 130 (143), never death by the signal, and the files are whole."""
    import time

    sig = signal.SIGINT if how == "int" else signal.SIGTERM
    proc = _cli_with_ctrl_c(
        "evolve", *BASE, "--seed", "0", "--generations", "100000", logdir=tmp_path
    )
    try:
        deadline = time.monotonic() + 180
        while not any(tmp_path.glob("*/summary.json")):  # generation 0 recorded
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
            time.sleep(0.05)
        proc.send_signal(sig)
        time.sleep(0.05)
        while proc.poll() is None and time.monotonic() < deadline:
            proc.send_signal(sig)
            time.sleep(0.05)
        errs = proc.stderr.read()
        proc.wait(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == (130 if how == "int" else 143), errs
    assert "Traceback" not in errs, errs
    (run,) = list(tmp_path.iterdir())
    held = load_checkpoint(run)["generation"]
    assert held >= 1
    assert json.loads((run / "summary.json").read_text())["generation"] == held - 1
    assert _named_checkpoint(errs) == held - 1, errs
    r = invoke("evolve", "--resume", run, "--generations", held + 1, *RFAST)
    assert r.exit_code == 0, r.output
