"""Reliability: files the tool reads cannot run code, damaged files give one-line errors."""

import io
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from swarmcode_torch.app.cli import app
from swarmcode_torch.app.runs import RunError, load_checkpoint, read_checkpoint

runner = CliRunner()
TINY = [
    "--scenario",
    "one-niche",
    "--population",
    "6",
    "--swarm-size",
    "4",
    "--trials",
    "1",
    "--ticks",
    "10",
    "--seed",
    "3",
]


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def one_line_error(result, *needles, stdout_ok: bool = False):
    """Exit 2, no traceback, and the error is one line (on stderr; with `stdout_ok`, what the
    run printed before it failed is allowed on stdout)."""
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    text = result.stderr if stdout_ok else result.output
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, result.output
    assert lines[0].startswith("Error: "), result.output
    for n in needles:
        assert n in lines[0], result.output


class Payload:
    """Unpickling this calls open(marker, 'w'): a file appears if the payload runs."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    logdir = tmp_path_factory.mktemp("runs")
    r = invoke("evolve", *TINY, "--generations", 2, "--logdir", logdir)
    assert r.exit_code == 0, r.output
    (run,) = list(logdir.iterdir())
    return run


def _copy_run(run: Path, to: Path) -> Path:
    to.mkdir()
    for f in run.iterdir():
        if f.is_file():
            (to / f.name).write_bytes(f.read_bytes())
    return to


def _poison(run: Path, marker: Path, where: str) -> None:
    d = torch.load(run / "checkpoint.pt", weights_only=True)
    if where == "top":
        d["extra"] = Payload(marker)
    else:  # hidden deep inside the history records
        d["history"][0]["population"] = Payload(marker)
    buf = io.BytesIO()
    torch.save(d, buf)
    (run / "checkpoint.pt").write_bytes(buf.getvalue())


@pytest.mark.parametrize("where", ["top", "nested"])
def test_a_checkpoint_with_a_reduce_payload_is_refused_and_the_payload_never_runs(
    finished_run, tmp_path, where
):
    run = _copy_run(finished_run, tmp_path / "run")
    marker = tmp_path / "PWNED"
    _poison(run, marker, where)
    # the payload is real: an unrestricted unpickler runs it
    torch.load(run / "checkpoint.pt", weights_only=False)
    assert marker.exists()
    marker.unlink()

    with pytest.raises(RunError, match="would run code"):
        load_checkpoint(run)
    assert not marker.exists()
    r = invoke("evolve", "--resume", run, "--generations", 3)
    one_line_error(r, "would run code", "checkpoint.pt")
    assert not marker.exists()


def test_a_genuine_checkpoint_loads_with_only_plain_types(finished_run):
    d = load_checkpoint(finished_run)
    assert d["generation"] == 2 and isinstance(d["rng_state"], torch.Tensor)
    assert isinstance(d["config"], dict) and isinstance(d["history"], list)


@pytest.mark.parametrize(
    "damage", ["truncated", "garbage", "empty", "not-a-dict", "missing-key", "wrong-type"]
)
def test_a_damaged_checkpoint_is_a_one_line_error(finished_run, tmp_path, damage):
    run = _copy_run(finished_run, tmp_path / "run")
    path = run / "checkpoint.pt"
    data = path.read_bytes()
    if damage == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif damage == "garbage":
        path.write_bytes(b"\x80\x04not a checkpoint at all" * 10)
    elif damage == "empty":
        path.write_bytes(b"")
    else:
        d = torch.load(path, weights_only=True)
        if damage == "not-a-dict":
            d = [1, 2, 3]
        elif damage == "missing-key":
            del d["rng_state"]
        else:
            d["genome"] = "oops"
        buf = io.BytesIO()
        torch.save(d, buf)
        path.write_bytes(buf.getvalue())
    with pytest.raises(RunError):
        read_checkpoint(path)
    one_line_error(invoke("evolve", "--resume", run, "--generations", 3), "checkpoint")


# ====================================================================== nothing is lost
import errno  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import signal  # noqa: E402
import socket  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402

from swarmcode_torch.app import checkpoints as checkpoints_module  # noqa: E402
from swarmcode_torch.app import files as files_module  # noqa: E402
from swarmcode_torch.app import runconfig as runconfig_module  # noqa: E402
from swarmcode_torch.app import runs as runs_module  # noqa: E402
from swarmcode_torch.app.runs import (  # noqa: E402
    LOCK_FILE,
    RunLock,
    clean_temporary_files,
    new_run_dir,
    repair_teams,
)

FAST = ["--render-every", "0", "--no-compile", "--device", "cpu"]
RFAST = ["--render-every", "0", "--device", "cpu"]  # what --resume may be given
REPO = Path(__file__).resolve().parents[2]


def _teams(run: Path) -> list[dict]:
    lines = (run / "teams.jsonl").read_text().splitlines()
    return [json.loads(line) for line in lines]  # every line is a whole record


def test_a_cut_off_teams_line_is_set_aside_on_resume_not_glued(finished_run, tmp_path):
    run = _copy_run(finished_run, tmp_path / "run")
    cut = '{"generation": 2, "fitness": 1.23, "desi'  # a kill in the middle of an append
    with open(run / "teams.jsonl", "a") as f:
        f.write(cut)
    r = invoke("evolve", "--resume", run, "--generations", 3, *RFAST)
    assert r.exit_code == 0, r.output
    assert [t["generation"] for t in _teams(run)] == [0, 1, 2]
    assert (run / "teams.jsonl.partial").read_text() == cut + "\n"
    assert repair_teams(run) == 0  # whole now: nothing more to do


def test_repair_teams_without_any_newline_and_with_a_long_tail(tmp_path):
    (tmp_path / "teams.jsonl").write_bytes(b"x" * 100_000)  # one cut line, longer than a chunk
    assert repair_teams(tmp_path) == 100_000
    assert (tmp_path / "teams.jsonl").read_bytes() == b""
    (tmp_path / "teams.jsonl").write_bytes(b'{"a": 1}\n' + b"y" * 70_000)
    assert repair_teams(tmp_path) == 70_000
    assert (tmp_path / "teams.jsonl").read_bytes() == b'{"a": 1}\n'
    assert (
        tmp_path / "teams.jsonl.partial"
    ).read_bytes() == b"x" * 100_000 + b"\n" + b"y" * 70_000 + b"\n"


_WRITER = """
import sys
from pathlib import Path
from swarmcode_torch.app import files
target, whole_write = Path(sys.argv[1]), files._write_all
files.atomic_write_bytes(target, bytes([1]) * (8 << 20))        # the old version, whole


def half_then_wait(fd, data):
    whole_write(fd, data[: len(data) // 2])
    print("mid-write", flush=True)                               # the kill lands here
    sys.stdin.read()


files._write_all = half_then_wait
files.atomic_write_bytes(target, bytes([2]) * (8 << 20))
"""


@pytest.mark.subprocess
def test_a_killed_atomic_write_leaves_the_old_file_whole_and_cleanup_removes_its_temp(tmp_path):
    # the writer stops half-way through its second write and says so: the kill lands there
    d = tmp_path
    target = d / "checkpoint.pt"
    proc = subprocess.Popen(
        [sys.executable, "-c", _WRITER, str(target)],
        cwd=REPO,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout.readline() == "mid-write\n"
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == -signal.SIGKILL
    assert target.read_bytes() == bytes([1]) * (8 << 20)  # the old version, whole
    (leftover,) = d.glob(".checkpoint.pt.*")
    assert leftover.read_bytes() == bytes([2]) * (4 << 20)  # the half-written new one
    (d / ".hidden").write_text("not ours")  # other hidden files are left alone
    assert clean_temporary_files(d) == [leftover]
    assert not list(d.glob(".checkpoint.pt.*")) and (d / ".hidden").exists()
    assert (d / "checkpoint.pt").stat().st_size == 8 << 20


def test_a_run_start_and_resume_remove_temporary_files_of_killed_writes(finished_run, tmp_path):
    run = _copy_run(finished_run, tmp_path / "run")
    junk = [
        run / ".checkpoint.pt.ab12cd34",
        run / ".summary.json.zz_9xy00",
        run / ".config.toml.q1w2e3r4",
    ]
    for j in junk:
        j.write_bytes(b"half a write")
    r = invoke("evolve", "--resume", run, "--generations", 3, *RFAST)
    assert r.exit_code == 0, r.output
    assert not any(j.exists() for j in junk)


class _DiskFull:
    """os.write that fills the disk on the `nth` write to a file named `name` (or a temporary
    file of it): it writes half of the bytes, then raises ENOSPC, as a full disk does."""

    def __init__(self, name: str, nth: int):
        self.name, self.nth, self.count, self.real = name, nth, 0, os.write

    def __call__(self, fd, data):
        try:
            path = os.path.basename(os.readlink(f"/proc/self/fd/{fd}"))
        except OSError:
            path = ""
        if path == self.name or path.startswith(f".{self.name}."):
            self.count += 1
            if self.count >= self.nth:
                self.real(fd, bytes(data[: len(data) // 2]))
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return self.real(fd, data)


def _full_disk_line(r, run: Path, generation: int):
    last = (
        f"last checkpoint after generation {generation - 1} "
        if generation
        else "last checkpoint before generation 0 "
    )
    one_line_error(
        r, "No space left on device", last, f"swarmcode-torch evolve --resume {run}", stdout_ok=True
    )
    assert load_checkpoint(run)["generation"] == generation  # the previous one, intact
    assert not list(run.glob(".checkpoint.pt.*")) and not list(run.glob(".summary.json.*"))
    assert not (run / LOCK_FILE).exists()


@pytest.mark.parametrize(
    "name,nth",
    [
        ("checkpoint.pt", 3),  # gen 0, 2 written; 4 fails
        ("summary.json", 3),  # generation 3's summary
        ("teams.jsonl", 3),
    ],
)  # generation 3's record
def test_a_full_disk_ends_the_run_in_one_line_with_the_last_checkpoint_intact(
    tmp_path, monkeypatch, name, nth
):
    full = _DiskFull(name, nth)
    monkeypatch.setattr(os, "write", full)
    r = invoke(
        "evolve", *TINY, "--generations", 4, "--checkpoint-every", 2, *FAST, "--logdir", tmp_path
    )
    monkeypatch.undo()
    assert full.count == nth
    (run,) = list(tmp_path.iterdir())
    _full_disk_line(r, run, 2)
    r = invoke("evolve", "--resume", run, *RFAST)  # space freed: it continues
    assert r.exit_code == 0, r.output
    assert [t["generation"] for t in _teams(run)][-2:] == [2, 3]
    assert load_checkpoint(run)["generation"] == 4


def test_a_full_disk_in_tensorboard_ends_the_run_in_one_line(tmp_path, monkeypatch):
    from tensorboard.summary.writer import record_writer

    state = {"full": False}
    real_save, real_write = checkpoints_module.save_checkpoint, record_writer.RecordWriter.write

    def save(run_dir, ev):
        path = real_save(run_dir, ev)
        state["full"] = ev.state.generation >= 2  # the disk fills after generation 2
        return path

    def write(self, data):
        if state["full"]:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_write(self, data)

    monkeypatch.setattr(checkpoints_module, "save_checkpoint", save)
    monkeypatch.setattr(record_writer.RecordWriter, "write", write)
    r = invoke(
        "evolve", *TINY, "--generations", 4, "--checkpoint-every", 2, *FAST, "--logdir", tmp_path
    )
    monkeypatch.undo()
    (run,) = list(tmp_path.iterdir())
    _full_disk_line(r, run, 2)


def test_a_real_full_disk_dev_full_is_one_line(finished_run, tmp_path, monkeypatch):
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full")
    run = _copy_run(finished_run, tmp_path / "run")
    # teams.jsonl opened for appending is /dev/full: every write to it is ENOSPC, for real (a
    # link to /dev/full is refused: test_links_planted_in_a_run_directory_are_never_followed)
    real_open = os.open

    def to_dev_full(path, flags, *args, **kw):
        if os.path.basename(os.fspath(path)) == "teams.jsonl" and flags & os.O_APPEND:
            return real_open("/dev/full", os.O_WRONLY)
        return real_open(path, flags, *args, **kw)

    monkeypatch.setattr(os, "open", to_dev_full)
    r = invoke("evolve", "--resume", run, "--generations", 4, *RFAST)
    monkeypatch.undo()
    _full_disk_line(r, run, 2)


# ====================================================================== a run owns its directory
def _wait_for(path_glob, base: Path, proc, timeout=180):
    deadline = time.monotonic() + timeout
    while not list(base.glob(path_glob)):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.2)
    return list(base.glob(path_glob))[0]


@pytest.mark.subprocess
def test_a_live_run_refuses_a_second_process_and_a_killed_runs_lock_is_taken_over(tmp_path):
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "swarmcode_torch.app.cli",
            "evolve",
            *TINY,
            "--generations",
            "100000",
            "--checkpoint-every",
            "1",
            *FAST,
            "--logdir",
            str(tmp_path),
        ],
        cwd=REPO,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        run = _wait_for("*/summary.json", tmp_path, proc).parent
        lock = (run / LOCK_FILE).read_text()
        assert f"pid={proc.pid} host={socket.gethostname()}" in lock
        r = invoke("evolve", "--resume", run, "--generations", 200000, *RFAST)
        one_line_error(r, "in use by a live run", f"pid={proc.pid}")
        proc.send_signal(signal.SIGKILL)  # dies without releasing: a stale lock
        proc.wait(timeout=60)
    finally:
        proc.kill()
    assert f"pid={proc.pid}" in (run / LOCK_FILE).read_text()
    gen = load_checkpoint(run)["generation"]
    r = invoke("evolve", "--resume", run, "--generations", gen + 1, *RFAST)
    assert r.exit_code == 0, r.output  # the dead pid's lock is taken over
    assert not (run / LOCK_FILE).exists()  # and released at the end


@pytest.mark.subprocess
def test_a_live_sweep_refuses_a_second_sweep_and_resume_and_sigterm_releases_its_locks(tmp_path):
    out = tmp_path / "sweep"
    args = [
        "sweep",
        "--budgets",
        "1500",
        "--seeds",
        "0",
        "--scenario",
        "one-niche",
        "--population",
        "6",
        "--swarm-size",
        "4",
        "--trials",
        "1",
        "--ticks",
        "10",
        "--device",
        "cpu",
        "--no-compile",
        "--checkpoint-every",
        "1",
        "--out",
        str(out),
    ]
    proc = subprocess.Popen(
        [sys.executable, "-m", "swarmcode_torch.app.cli", *args, "--generations", "100000"],
        cwd=REPO,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        run = _wait_for("*/summary.json", out, proc).parent
        assert (out / "sweep.lock").is_file() and (run / LOCK_FILE).is_file()
        one_line_error(
            invoke(*args, "--generations", 100000),
            "in use by a live run",
            f"pid={proc.pid}",
            "sweep.lock",
        )
        one_line_error(
            invoke("evolve", "--resume", run, "--generations", 100000, *RFAST),
            "in use by a live run",
            f"pid={proc.pid}",
            LOCK_FILE,
        )
        proc.send_signal(signal.SIGTERM)
        _, errs = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 143, errs
    assert not (out / "sweep.lock").exists() and not (run / LOCK_FILE).exists()


def test_the_lock_is_released_on_an_error_and_on_ctrl_c(finished_run, tmp_path, monkeypatch):
    run = _copy_run(finished_run, tmp_path / "run")
    with RunLock(run):  # held in this process: refused too
        one_line_error(
            invoke("evolve", "--resume", run, "--generations", 3, *RFAST),
            "in use by a live run",
            f"pid={os.getpid()}",
        )
    assert not (run / LOCK_FILE).exists()
    good = (run / "config.toml").read_text()
    (run / "config.toml").write_text(good.replace("seed = 3", "seed = 4"))
    one_line_error(invoke("evolve", "--resume", run, "--generations", 3, *RFAST), "seed")
    assert not (run / LOCK_FILE).exists()  # released on the error
    (run / "config.toml").write_text(good)
    from swarmcode_torch.coevo.evolve import Evolution

    def interrupted(self):
        raise KeyboardInterrupt

    monkeypatch.setattr(Evolution, "step", interrupted)
    r = invoke("evolve", "--resume", run, "--generations", 3, *RFAST)
    assert r.exit_code == 130 and "Interrupted" in r.output
    assert not (run / LOCK_FILE).exists()  # released on Ctrl-C


@pytest.mark.subprocess
def test_a_stale_lock_of_a_dead_pid_is_taken_over(finished_run, tmp_path):
    run = _copy_run(finished_run, tmp_path / "run")
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (run / LOCK_FILE).write_text(f"pid={dead.pid} host={socket.gethostname()} since=then\n")
    r = invoke("evolve", "--resume", run, "--generations", 3, *RFAST)
    assert r.exit_code == 0, r.output
    assert not (run / LOCK_FILE).exists()


def test_run_directories_made_at_the_same_second_never_collide(tmp_path, monkeypatch):
    from swarmcode_torch.coevo.config import SwarmCoDeConfig

    monkeypatch.setattr(files_module.time, "strftime", lambda fmt, *when: "20250101-000000")
    n = 12
    barrier, made, errors = threading.Barrier(n), [], []

    def make():
        barrier.wait()
        try:
            made.append(new_run_dir(tmp_path / "logs", SwarmCoDeConfig(scenario="budget")))
        except Exception as e:  # noqa: BLE001
            errors.append(e)

    threads = [threading.Thread(target=make) for _ in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(set(made)) == n
    assert sorted(p.name for p in made)[0] == "budget__0__20250101-000000"


# ====================================================================== a run is self-contained
MINE = """name = "mine"
description = "a custom world"
arena = 14.0
base_radius = 1.0
num_robots = 4
episode_ticks = 10

[[packages]]
kind = "individual"
effector = "pincher"
count = 3
distance = [2.5, 5.0]
mass = [1.0, 3.0]
"""


def test_a_run_keeps_its_scenario_and_resumes_and_replays_it_from_anywhere(tmp_path, monkeypatch):
    from swarmcode_torch.app.runs import hardware_bytes
    from swarmcode_torch.app.runs import resume as resume_run

    work, elsewhere = tmp_path / "work", tmp_path / "elsewhere"
    work.mkdir()
    elsewhere.mkdir()
    (work / "mine.toml").write_text(MINE)
    monkeypatch.chdir(work)
    r = invoke(
        "evolve",
        "--scenario",
        "mine.toml",
        "--population",
        6,
        "--trials",
        1,
        "--generations",
        2,
        *FAST,
        "--logdir",
        "runs",
    )
    assert r.exit_code == 0, r.output
    (run,) = [p.resolve() for p in (work / "runs").iterdir()]
    assert (run / "scenario.toml").read_text() == MINE
    assert (run / "hardware.toml").read_bytes() == hardware_bytes()
    assert 'scenario = "mine.toml"' in (run / "config.toml").read_text()
    # the original changes into another valid world, then goes away; we work from elsewhere
    (work / "mine.toml").write_text(MINE.replace("arena = 14.0", "arena = 30.0"))
    monkeypatch.chdir(elsewhere)
    ev = resume_run(run, generations=3)
    assert ev.ctx.scenario.arena == 14.0 and ev.cfg.scenario == "mine.toml"
    (work / "mine.toml").unlink()
    r = invoke("evolve", "--resume", run, "--generations", 3, *RFAST)
    assert r.exit_code == 0, r.output
    assert load_checkpoint(run)["config"]["scenario"] == "mine.toml"
    assert json.loads((run / "summary.json").read_text())["scenario"] == "mine.toml"
    r = invoke("replay", run, "--ticks", 4, "--out", elsewhere / "t.gif")
    assert r.exit_code == 0, r.output
    assert (elsewhere / "t.gif").is_file()
    r = invoke("inspect", run)
    assert r.exit_code == 0 and "lifts:" in r.output, r.output


def test_a_run_made_before_runs_kept_copies_still_resumes_and_replays(finished_run, tmp_path):
    run = _copy_run(finished_run, tmp_path / "run")
    (run / "scenario.toml").unlink()
    (run / "hardware.toml").unlink()
    # such a run's checkpoint has no digests of its copies ("run_files"); with them, a copy
    # that went missing is refused (test_an_edited_or_missing_copy_is_refused_on_resume)
    d = torch.load(run / "checkpoint.pt", weights_only=True)
    del d["run_files"]
    torch.save(d, run / "checkpoint.pt")
    r = invoke("evolve", "--resume", run, "--generations", 3, *RFAST)
    assert r.exit_code == 0, r.output
    assert not (run / "scenario.toml").exists()  # no copy made up after the fact
    r = invoke("replay", run, "--ticks", 4, "--out", tmp_path / "t.gif")
    assert r.exit_code == 0, r.output


def test_a_run_whose_catalog_differs_from_the_installed_one_resumes_with_its_own(
    finished_run, tmp_path
):
    from swarmcode_torch.app.runs import resume as resume_run

    run = _copy_run(finished_run, tmp_path / "run")
    text = (run / "hardware.toml").read_text()
    import re

    changed = re.sub(
        r"(?m)^(\s*mass\s*=\s*)([0-9.]+)", lambda m: m.group(1) + "9.75", text, count=1
    )
    assert changed != text
    (run / "hardware.toml").write_text(changed)  # as if the installed catalog had changed
    d = torch.load(run / "checkpoint.pt", weights_only=True)  # since the run started with it
    d["run_files"] = runs_module.copy_digests(run)
    torch.save(d, run / "checkpoint.pt")
    assert resume_run(run, generations=3).ctx.scenario.hardware.base_mass == 9.75
    r = invoke("evolve", "--resume", run, "--generations", 3, *RFAST)
    assert r.exit_code == 0, r.output
    r = invoke("replay", run, "--ticks", 4, "--out", tmp_path / "t.gif")
    assert r.exit_code == 0, r.output


def test_a_config_toml_that_differs_from_the_checkpoint_names_the_keys(finished_run, tmp_path):
    run = _copy_run(finished_run, tmp_path / "run")
    good = (run / "config.toml").read_text()
    (run / "config.toml").write_text(
        good.replace("seed = 3", "seed = 4").replace("delta = 0.4", "delta = 0.5")
    )
    one_line_error(
        invoke("evolve", "--resume", run, "--generations", 3, *RFAST),
        "does not match",
        "differing keys: delta, seed",
    )
    (run / "config.toml").write_text(good.replace("generations = 2", "generations = 3"))
    r = invoke("evolve", "--resume", run, *RFAST)  # generations may differ
    assert r.exit_code == 0, r.output


def _snapshot(run: Path) -> dict:
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in run.iterdir()}


@pytest.mark.parametrize("asked", [None, 1, 2])
def test_resume_to_no_more_generations_changes_nothing(finished_run, tmp_path, asked):
    run = _copy_run(finished_run, tmp_path / "run")
    before = _snapshot(run)
    r = invoke("evolve", "--resume", run, *([] if asked is None else ["--generations", asked]))
    assert r.exit_code == 0, r.output
    assert "already has 2 generations" in r.output and "nothing to do" in r.output
    assert _snapshot(run) == before  # no file written, none added


def test_logdir_with_resume_is_refused(finished_run, tmp_path):
    one_line_error(
        invoke("evolve", "--resume", finished_run, "--logdir", tmp_path),
        "--logdir cannot be used with --resume",
    )


# ====================================================================== every value is checked
@pytest.mark.parametrize(
    "args,needles",
    [
        (["--budget", "nan"], ["--budget must be a finite number"]),
        (["--budget", "inf"], ["--budget must be a finite number"]),
        (["--budget", "-inf"], ["--budget must be a finite number"]),
        (["--seed", str(2**63)], ["--seed must be in [0, 9223372036854775807]"]),
        (["--seed", "-1"], ["--seed must be >= 0"]),
        (["--population", "1000000000000"], ["would need about", "PiB", "--population"]),
        (["--set", "bt_length=100000000000"], ["would need about", "TiB"]),
        (["--set", "bt_length=100000"], ["--set bt_length must be <= 4096"]),
        (["--set", "tag_length=0"], ["--set tag_length must be >= 1"]),
        (["--set", "alpha=1.5"], ["--set alpha must be <= 1"]),
        (["--set", "p_marginal=-0.1"], ["--set p_marginal must be a finite number in [0, 1]"]),
        (["--set", "delta=0"], ["--set delta must be a finite number > 0"]),
        (["--set", "lam=inf"], ["--set lam must be a finite number >= 0"]),
        (["--set", "hw_sigma=nan"], ["--set hw_sigma must be a finite number >= 0"]),
        (["--set", "min_share=-1"], ["--set min_share must be a finite number >= 0"]),
        (["--set", "p_gene_mutation=2"], ["--set p_gene_mutation must be <= 1"]),
        (["--set", "delta=0.5", "--set", "delta=0.6"], ["--set delta is given twice"]),
        (["--generations", "1000000000"], ["--generations must be <= 10000000"]),
        (["--ticks", "1000000000"], ["--ticks must be <= 1000000"]),
        (["--trials", "100000000000"], ["would need about", "--trials"]),
        (["--device", "cuda:x"], ["--device must be auto, cpu, cuda or cuda:N"]),
    ],
)
def test_options_and_set_values_are_checked_before_anything_is_made(tmp_path, args, needles):
    one_line_error(invoke("evolve", "--logdir", tmp_path / "runs", *args), *needles)
    assert not (tmp_path / "runs").exists()


def _scenario(tmp_path: Path, text: str, name="s.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "change,needles",
    [
        (("mass = [1.0, 3.0]", "mass = [nan, 3.0]"), ["packages[0].mass", "finite"]),
        (("distance = [2.5, 5.0]", "distance = [2.5, nan]"), ["packages[0].distance", "finite"]),
        (("arena = 14.0", "arena = inf"), ["arena: expected a finite number"]),
        (("arena = 14.0", "arena = 20000.0"), ["arena: must be in (0, 10000] m"]),
        (
            ("distance = [2.5, 5.0]", "distance = [2.5, 30.0]"),
            ["packages[0].distance", "outside the arena"],
        ),
        (
            ("distance = [2.5, 5.0]", "distance = [8.0, 9.0]"),
            ["packages[0].distance", "outside the arena in most directions"],
        ),
        (
            ("distance = [2.5, 5.0]", "distance = [0.5, 5.0]"),
            ["packages[0].distance", "inside the base"],
        ),
        (("count = 3", "count = 400"), ["packages[0].count", "do not fit"]),
        (
            ("mass = [1.0, 3.0]", "mass = [1.0, 3.0]\nradius_band = [0.6, 0.9]"),
            ["packages[0].radius_band", "no robot radius", "0.15-0.5"],
        ),
        (
            (
                "episode_ticks = 10",
                "episode_ticks = 10\n[obstacles]\ncount = 100\nradius = [1.0, 1.5]",
            ),
            ["obstacles", "more than half"],
        ),
        (
            (
                "episode_ticks = 10",
                "episode_ticks = 10\n[obstacles]\ncount = 1\nradius = [7.0, 7.5]",
            ),
            ["obstacles.radius", "does not fit"],
        ),
        (
            ("distance = [2.5, 5.0]", 'distance = "far"'),
            ["packages[0].distance: expected [low, high], got 'far'"],
        ),
        (
            ("num_robots = 4", "num_robots = 10000000000"),
            ["would need about", "10000000000 robots"],
        ),
        (("num_robots = 4", "num_robots = 4.5"), ["num_robots: expected int"]),
        (("[[packages]]", "[[packagez]]"), ["packagez: unknown field"]),
    ],
)
def test_a_scenario_file_is_checked_field_by_field(tmp_path, change, needles):
    path = _scenario(tmp_path, MINE.replace(*change))
    assert MINE.replace(*change) != MINE
    r = invoke(
        "evolve",
        "--scenario",
        path,
        "--population",
        6,
        "--trials",
        1,
        "--logdir",
        tmp_path / "runs",
    )
    one_line_error(r, str(path), *needles)
    assert not (tmp_path / "runs").exists()


def test_a_scenario_without_packages_keeps_its_brackets_in_the_message(tmp_path):
    path = _scenario(tmp_path, MINE[: MINE.index("[[packages]]")])
    one_line_error(
        invoke("evolve", "--scenario", path, "--logdir", tmp_path / "runs"),
        "expected at least one [[packages]] table",
    )


def test_a_scenario_with_a_byte_order_mark_is_read(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + MINE.encode())
    r = invoke(
        "evolve",
        "--scenario",
        path,
        "--population",
        4,
        "--trials",
        1,
        "--ticks",
        5,
        "--generations",
        1,
        *FAST,
        "--logdir",
        tmp_path / "runs",
    )
    assert r.exit_code == 0, r.output
    (run,) = list((tmp_path / "runs").iterdir())
    assert (run / "scenario.toml").read_bytes() == path.read_bytes()  # kept as read


def test_undecodable_run_files_and_scenarios_name_the_file(finished_run, tmp_path):
    bad = _scenario(tmp_path, "")
    bad.write_bytes(b'name = "\xff\xfe"\n')
    one_line_error(
        invoke("evolve", "--scenario", bad, "--logdir", tmp_path / "runs"), str(bad), "not UTF-8"
    )
    for name, command in (
        ("config.toml", ["evolve", "--resume", "RUN", "--generations", 3]),
        ("summary.json", ["inspect", "RUN"]),
        ("teams.jsonl", ["replay", "RUN", "--generation", 1]),
    ):
        run = _copy_run(finished_run, tmp_path / f"run-{name}")
        (run / name).write_bytes((run / name).read_bytes() + b"\xc3\x28 \xff\n")
        one_line_error(
            invoke(*[run if a == "RUN" else a for a in command]), str(run / name), "not UTF-8"
        )


@pytest.mark.parametrize(
    "name,edit,command,needles",
    [
        (
            "config.toml",
            ("population = 6", "population = 6.5"),
            "resume",
            ["population must be an integer"],
        ),
        (
            "config.toml",
            ("delta = 0.4", "delta = nan"),
            "replay",
            ["config.toml", "delta must be a finite number"],
        ),
        ("config.toml", ("seed = 3", "seed = -3"), "replay", ["seed must be >= 0"]),
        (
            "config.toml",
            ("population = 6", "population = [6]"),
            "resume",
            ["population: expected a single value"],
        ),
        (
            "summary.json",
            ('"radius": ', '"radius": "big", "x": '),
            "inspect",
            ["designs[0].radius", "big"],
        ),
        (
            "summary.json",
            ('"best_fitness": ', '"best_fitness": "high", "x": '),
            "inspect",
            ["best_fitness: expected a number"],
        ),
        (
            "summary.json",
            ('"designs": [', '"designs": [7, '),
            "replay",
            ["designs[0]: expected a table"],
        ),
        (
            "teams.jsonl",
            ('"chassis_tier": ', '"chassis_tier": 9, "x": '),
            "replay1",
            ["generation 1", "designs[0].chassis_tier"],
        ),
    ],
)
def test_run_files_read_back_are_checked(finished_run, tmp_path, name, edit, command, needles):
    run = _copy_run(finished_run, tmp_path / "run")
    text = (run / name).read_text()
    assert edit[0] in text
    (run / name).write_text(text.replace(edit[0], edit[1]))
    args = {
        "resume": ["evolve", "--resume", run, "--generations", 3],
        "replay": ["replay", run, "--out", tmp_path / "t.gif"],
        "replay1": ["replay", run, "--generation", 1, "--out", tmp_path / "t.gif"],
        "inspect": ["inspect", run],
    }[command]
    one_line_error(invoke(*args), str(run / name), *needles)


# ====================================================================== file-system failures
def test_a_logdir_that_is_a_file_or_under_proc_is_one_line(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    tiny = [*TINY, "--generations", 1, *FAST]
    one_line_error(invoke("evolve", *tiny, "--logdir", f), f"--logdir {f} is not a directory")
    one_line_error(invoke("evolve", *tiny, "--logdir", f / "sub"), "--logdir", "Not a directory")
    one_line_error(
        invoke("evolve", *tiny, "--logdir", "/proc/swarmcode-runs"),
        "--logdir /proc/swarmcode-runs: cannot make a run directory",
    )


def test_a_read_only_logdir_is_one_line(tmp_path, monkeypatch):
    # a read-only file system (EROFS) from the directory's creation, as a read-only mount gives
    def read_only(self, *a, **k):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(self))

    monkeypatch.setattr(Path, "mkdir", read_only)
    r = invoke("evolve", *TINY, "--generations", 1, *FAST, "--logdir", tmp_path / "ro")
    monkeypatch.undo()
    one_line_error(r, "Read-only file system", str(tmp_path / "ro"))


@pytest.mark.skipif(
    os.name != "posix" or os.geteuid() == 0,
    reason="root reads and writes whatever the permissions say",
)
def test_unwritable_and_unreadable_paths_are_one_line(finished_run, tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    one_line_error(
        invoke("evolve", *TINY, "--generations", 1, *FAST, "--logdir", locked / "r"),
        "Permission denied",
    )
    run = _copy_run(finished_run, tmp_path / "run")
    for name, command in (
        ("summary.json", ["inspect", run]),
        ("config.toml", ["replay", run, "--out", tmp_path / "t.gif"]),
    ):
        (run / name).chmod(0)
        one_line_error(invoke(*command), str(run / name), "Permission denied")
        (run / name).chmod(0o644)


def test_unreadable_run_files_are_one_line(finished_run, tmp_path, monkeypatch):
    # as root, chmod 000 does not deny a read: the read itself is made to fail with EACCES
    run = _copy_run(finished_run, tmp_path / "run")
    real, real_open = Path.read_bytes, os.open
    names = ("summary.json", "config.toml", "s.toml")

    def denied(self):
        if self.name in names:
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(self))
        return real(self)

    def denied_open(path, flags, *args, **kw):
        if os.path.basename(os.fspath(path)) in names and not flags & os.O_CREAT:
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), os.fspath(path))
        return real_open(path, flags, *args, **kw)

    scen = _scenario(tmp_path, MINE)
    monkeypatch.setattr(Path, "read_bytes", denied)
    monkeypatch.setattr(os, "open", denied_open)
    results = [
        (invoke("inspect", run), run / "summary.json"),
        (invoke("replay", run, "--out", tmp_path / "t.gif"), run / "config.toml"),
        (invoke("evolve", "--scenario", scen, "--logdir", tmp_path / "x"), scen),
    ]
    monkeypatch.undo()
    for r, path in results:
        one_line_error(r, str(path), "Permission denied")


def test_replay_into_a_missing_folder_and_sweep_into_a_file_are_one_line(finished_run, tmp_path):
    one_line_error(
        invoke("replay", finished_run, "--out", tmp_path / "no" / "t.gif"),
        "--out",
        "does not exist",
    )
    one_line_error(invoke("replay", finished_run, "--out", tmp_path), "is a directory")
    f = tmp_path / "file"
    f.write_text("x")
    one_line_error(
        invoke("sweep", "--budgets", "1500", "--scenario", "one-niche", "--out", f),
        f"--out {f} is not a directory",
    )


# ====================================================================== umask
@pytest.mark.parametrize("umask,mode", [(0o022, 0o644), (0o077, 0o600)])
def test_run_files_are_shared_as_the_umask_allows(tmp_path, umask, mode):
    old = os.umask(umask)
    try:
        r = invoke("evolve", *TINY, "--generations", 1, *FAST, "--logdir", tmp_path)
    finally:
        os.umask(old)
    assert r.exit_code == 0, r.output
    (run,) = list(tmp_path.iterdir())
    for name in (
        "checkpoint.pt",
        "config.toml",
        "summary.json",
        "scenario.toml",
        "hardware.toml",
        "teams.jsonl",
    ):
        assert (run / name).stat().st_mode & 0o777 == mode, name


# ====================================================================== sweeps
SWEEP = [
    "sweep",
    "--budgets",
    "1500",
    "--seeds",
    "0",
    "--scenario",
    "one-niche",
    "--generations",
    1,
    "--population",
    6,
    "--swarm-size",
    4,
    "--trials",
    1,
    "--ticks",
    10,
    "--device",
    "cpu",
    "--no-compile",
]


def test_a_sweep_into_an_out_of_other_settings_is_refused(tmp_path):
    out = tmp_path / "sweep"
    r = invoke(*SWEEP, "--out", out)
    assert r.exit_code == 0, r.output
    for change, keys in (
        ((("--population", 6), ("--population", 8)), "population"),
        ((("--trials", 1), ("--trials", 2)), "trials"),
        ((("--ticks", 10), ("--ticks", 12)), "ticks"),
        ((("--scenario", "one-niche"), ("--scenario", "two-niche")), "scenario"),
    ):
        args = list(SWEEP)
        i = args.index(change[0][0])
        args[i + 1] = change[1][1]
        one_line_error(invoke(*args, "--out", out), "other settings", f"differing keys: {keys}")
    one_line_error(invoke(*SWEEP, "--objective", "roi", "--out", out), "differing keys: objective")
    one_line_error(
        invoke(*SWEEP, "--set", "delta=0.5", "--set", "p_tag_flip=0.5", "--out", out),
        "differing keys: delta, p_tag_flip",
    )
    r = invoke(*SWEEP, "--out", out)  # the same sweep: already done
    assert r.exit_code == 0 and "already done" in r.output, r.output


def test_a_sweep_refuses_duplicated_or_non_finite_budgets_and_seeds(tmp_path):
    one_line_error(
        invoke("sweep", "--budgets", "1500,3000,1500", "--out", tmp_path / "a"),
        "--budgets lists 1500 twice",
    )
    one_line_error(
        invoke("sweep", "--seeds", "0,1,0", "--out", tmp_path / "a"), "--seeds lists 0 twice"
    )
    one_line_error(
        invoke("sweep", "--budgets", "1500,nan", "--out", tmp_path / "a"),
        "--budgets: nan is not a finite number",
    )
    one_line_error(
        invoke("sweep", "--seeds", str(2**64), "--out", tmp_path / "a"),
        "--seeds must be in [0, 9223372036854775807]",
    )
    assert not (tmp_path / "a").exists()


def test_a_sweep_table_from_a_damaged_summary_is_one_line(tmp_path):
    out = tmp_path / "sweep"
    assert invoke(*SWEEP, "--out", out).exit_code == 0
    summary = out / "budget-1500_seed-0" / "summary.json"
    summary.write_text(summary.read_text().replace('"team_cost": ', '"team_cost": "x", "y": '))
    one_line_error(
        invoke(*SWEEP, "--out", out), str(summary), "team_cost: expected a number", stdout_ok=True
    )


# ====================================================================== messages
def test_error_messages_keep_brackets_and_name_the_option(tmp_path):
    path = _scenario(tmp_path, MINE.replace("mass = [1.0, 3.0]", "mass = [3.0]"))
    r = invoke("evolve", "--scenario", path, "--logdir", tmp_path / "runs")
    one_line_error(r, "packages[0].mass: expected [low, high], got [3.0]")
    one_line_error(
        invoke("evolve", "--seed", str(2**64), "--logdir", tmp_path / "runs"), "--seed must be in"
    )
    one_line_error(invoke("replay", tmp_path, "--seed", str(2**64)), "--seed must be in")


# ====================================================================== bit-exact resume
def test_a_resumed_run_writes_the_same_records_as_one_straight_through(tmp_path):
    straight, parts = tmp_path / "straight", tmp_path / "parts"
    args = [*TINY, *FAST, "--checkpoint-every", 1]
    assert invoke("evolve", *args, "--generations", 4, "--logdir", straight).exit_code == 0
    assert invoke("evolve", *args, "--generations", 2, "--logdir", parts).exit_code == 0
    (a,), (b,) = list(straight.iterdir()), list(parts.iterdir())
    r = invoke("evolve", "--resume", b, "--generations", 4, *RFAST)
    assert r.exit_code == 0, r.output
    assert (a / "teams.jsonl").read_bytes() == (b / "teams.jsonl").read_bytes()
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (a, b))
    for s in (sa, sb):
        s["last_generation"] = {
            k: v for k, v in s["last_generation"].items() if not k.startswith("perf/")
        }  # timings
    assert sa == sb
    ca, cb = load_checkpoint(a), load_checkpoint(b)
    assert torch.equal(ca["rng_state"], cb["rng_state"]) and ca["history"] == cb["history"]
    assert all(torch.equal(ca["genome"][k], cb["genome"][k]) for k in ca["genome"])


def test_a_run_stopped_before_its_first_periodic_checkpoint_resumes_from_generation_0(
    tmp_path, monkeypatch
):
    from swarmcode_torch.coevo.evolve import Evolution

    def full(self):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Evolution, "step", full)
    r = invoke(
        "evolve", *TINY, "--generations", 2, "--checkpoint-every", 100, *FAST, "--logdir", tmp_path
    )
    monkeypatch.undo()
    (run,) = list(tmp_path.iterdir())
    _full_disk_line(r, run, 0)
    r = invoke("evolve", "--resume", run, *RFAST)
    assert r.exit_code == 0, r.output
    assert load_checkpoint(run)["generation"] == 2


def test_usage_errors_are_one_line(tmp_path):
    one_line_error(invoke("evolve", "--population", "abc"), "Invalid value for '--population'")
    one_line_error(invoke("evolve", "--no-such-option"), "No such option: --no-such-option")
    one_line_error(invoke("replay"), "Missing argument")


def test_a_run_too_big_for_this_machine_replays_and_inspects_but_does_not_resume(
    finished_run, tmp_path, monkeypatch
):
    run = _copy_run(finished_run, tmp_path / "run")
    monkeypatch.setattr(runconfig_module, "memory_limit", lambda device="auto": (1024, "memory"))
    r = invoke("replay", run, "--ticks", 4, "--out", tmp_path / "t.gif")
    assert r.exit_code == 0, r.output
    assert invoke("inspect", run).exit_code == 0
    one_line_error(
        invoke("evolve", "--resume", run, "--generations", 3, *RFAST),
        "would need about",
        "more than the 1 KiB of memory",
    )
