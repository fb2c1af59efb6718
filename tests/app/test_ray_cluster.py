"""Hostile inputs (issue 29): an unreachable Ray address and Ray workers that cannot start are
one line in time (docs/RELIABILITY.md)."""

from __future__ import annotations

import socket
import sys
import time

import pytest
from hostilekit import TINY, invoke, one_line_error


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("command", ["evolve", "sweep"])
def test_a_ray_address_that_is_closed_or_silent_is_one_line_in_time(tmp_path, monkeypatch, command):
    pytest.importorskip("ray")
    monkeypatch.setenv("SWARMCODE_RAY_CONNECT_TIMEOUT", "2")
    args = (
        ["evolve", *TINY, "--generations", 1, "--logdir", tmp_path / "r"]
        if command == "evolve"
        else [
            "sweep",
            "--budgets",
            "1000",
            "--generations",
            1,
            "--population",
            6,
            "--trials",
            1,
            "--ticks",
            5,
            "--device",
            "cpu",
            "--out",
            tmp_path / "s",
        ]
    )
    t = time.monotonic()
    one_line_error(
        invoke(*args, "--ray-address", f"127.0.0.1:{_free_port()}"),
        "cannot join the Ray cluster at 127.0.0.1:",
    )
    silent = socket.socket()  # accepts (the backlog) and never answers
    silent.bind(("127.0.0.1", 0))
    silent.listen(4)
    try:
        port = silent.getsockname()[1]
        one_line_error(
            invoke(*args, "--ray-address", f"127.0.0.1:{port}"),
            f"cannot join the Ray cluster at 127.0.0.1:{port}",
        )
    finally:
        silent.close()
    assert time.monotonic() - t < 30


@pytest.fixture
def ray_whose_workers_cannot_start(tmp_path):
    """A local Ray cluster (127.0.0.1 only, 2 CPUs) whose worker processes cannot start: they run
    under a virtual-memory limit (ulimit -v, as on shared clusters), so mapping the object store
    fails ("mmap failed") and no task or actor ever runs. The command line joins this session."""
    ray = pytest.importorskip("ray")
    if ray.is_initialized():
        pytest.skip("a Ray session is already open in this process")
    python = tmp_path / "python-under-ulimit"
    python.write_text(f'#!/bin/sh\nulimit -v 400000\nexec {sys.executable} "$@"\n')
    python.chmod(0o755)
    ray.init(
        num_cpus=2,
        include_dashboard=False,
        log_to_driver=False,
        _node_ip_address="127.0.0.1",  # loopback only
        runtime_env={"py_executable": str(python)},
    )
    try:
        yield ray
    finally:
        ray.shutdown()


@pytest.mark.subprocess
@pytest.mark.parametrize("command", ["sweep", "evolve"])
def test_ray_workers_that_cannot_start_are_one_line_in_time(
    ray_whose_workers_cannot_start, tmp_path, monkeypatch, command
):
    monkeypatch.setenv("SWARMCODE_RAY_START_TIMEOUT", "3")
    if command == "sweep":
        args = [
            "sweep",
            "--budgets",
            "1000",
            "--seeds",
            "0,1",
            "--generations",
            1,
            "--population",
            6,
            "--trials",
            1,
            "--ticks",
            5,
            "--device",
            "cpu",
            "--no-compile",
            "--out",
            tmp_path / "s",
            "--workers",
            2,
        ]
        needle = "Ray could not start 2 workers for the runs within 3 s"
    else:
        args = ["evolve", *TINY, "--generations", 1, "--logdir", tmp_path / "r"]
        args += ["--eval-workers", 2]
        needle = "Ray could not start 2 evaluation workers within 3 s"
    t = time.monotonic()
    line = one_line_error(invoke(*args), needle, "SWARMCODE_RAY_START_TIMEOUT")
    assert time.monotonic() - t < 30, line
    if command == "sweep":
        assert not (tmp_path / "s" / "table.csv").exists()
