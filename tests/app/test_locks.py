"""Reliability: a run owns its directory, its lock refuses a second process and is released
or taken over (docs/RELIABILITY.md)."""

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from runkit import FAST, REPO, RFAST, TINY, _copy_run, invoke, one_line_error, tiny_run

from swarmcode_torch.app import files as files_module
from swarmcode_torch.app.runs import LOCK_FILE, RunLock, load_checkpoint, new_run_dir


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    return tiny_run(tmp_path_factory)


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
