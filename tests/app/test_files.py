"""Reliability: nothing is lost (cut-off lines, killed writes, full disks) and file-system
failures are one line (docs/RELIABILITY.md)."""

import errno
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from runkit import (
    FAST,
    MINE,
    REPO,
    RFAST,
    TINY,
    _copy_run,
    _full_disk_line,
    _scenario,
    invoke,
    one_line_error,
    tiny_run,
)

from swarmcode_torch.app import checkpoints as checkpoints_module
from swarmcode_torch.app.runs import clean_temporary_files, load_checkpoint, repair_teams


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    return tiny_run(tmp_path_factory)


# ====================================================================== nothing is lost
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
