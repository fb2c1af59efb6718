"""Run-directory files: their names, atomic writes, appends, and reads that never follow a link.

A run directory holds everything the run needs to continue or be replayed: its config, its
checkpoint, the scenario TOML it ran on (scenario.toml) and the hardware catalog as it was read
(hardware.toml). A live run holds run.lock (its pid and host) so that no second process writes
into it. docs/RELIABILITY.md lists what the files promise and the tests that show it.
"""

from __future__ import annotations

import errno
import json
import os
import re
import stat
import tempfile
import time
from pathlib import Path

from ..coevo.config import SwarmCoDeConfig
from ..sim.hardware import MAX_NESTING, nesting_depth
from ..sim.reading import read_regular

CONFIG_FILE = "config.toml"
CHECKPOINT_FILE = "checkpoint.pt"
SUMMARY_FILE = "summary.json"
TEAMS_FILE = "teams.jsonl"
PARTIAL_SUFFIX = ".partial"  # teams.jsonl.partial: cut-off lines set aside on resume
SCENARIO_COPY = "scenario.toml"  # the scenario file the run ran on, as read
HARDWARE_COPY = "hardware.toml"  # the hardware catalog the run ran with, as read
LOCK_FILE = "run.lock"  # held by the live run: "pid=... host=..."
SWEEP_LOCK_FILE = "sweep.lock"  # held by a live sweep in its --out directory
METRICS_FILE = "metrics.csv"  # every scalar of every generation (reporting.CsvReporter)
REPLAY_FILE = "team.gif"  # the default output of `replay`
SNAPSHOT_DIR = "snapshots"  # snapshots/generation-000100.pt (--snapshot-every)
#: A sweep's outputs in its --out directory (sweep.write_outputs).
TABLE_MD, TABLE_CSV, BUDGET_PLOT = "table.md", "table.csv", "budget.png"
#: Files of a run directory written with `atomic_write_bytes`; a temporary `.NAME.xxxxxxxx` of
#: one of them (or of any file that exists) left by a killed write is removed on start.
ATOMIC_FILES = (
    CONFIG_FILE,
    CHECKPOINT_FILE,
    SUMMARY_FILE,
    SCENARIO_COPY,
    HARDWARE_COPY,
    METRICS_FILE,
    TEAMS_FILE,
    REPLAY_FILE,
    TABLE_MD,
    TABLE_CSV,
)
#: The most bytes read from a text file of a run or a scenario (config.toml, scenario.toml,
#: hardware.toml, summary.json; a scenario file and the catalog it names): far above any real
#: one, far below what would exhaust memory.
MAX_TEXT_BYTES = 16 * 2**20
#: The most bytes read from teams.jsonl and metrics.csv (one record a generation).
MAX_RECORD_BYTES = 2 * 2**30


class RunError(ValueError):
    """A run directory, config or checkpoint that cannot be used (one-line message)."""


def current_umask() -> int:
    """The process umask (read from /proc where it can be, so the umask is never changed)."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def interrupt_point(what: str) -> None:
    """Called after each step of a run that writes (a file replaced or appended to) and after
    each generation is computed; does nothing. Tests replace it to interrupt or kill a run at
    every such point (tests/app/test_reliability.py, the interrupt sweep)."""


def open_nofollow(path: Path, flags: int, mode: int = 0o666) -> int:
    """os.open that never follows a symbolic link at `path` (O_NOFOLLOW): a run's files are its
    own, and a link planted in a run directory must not make a run read or write elsewhere.
    OSError (ELOOP) for a link, reported as "is a symbolic link"."""
    try:
        return os.open(
            path, flags | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0), mode
        )
    except OSError as e:
        if e.errno == errno.ELOOP or (e.errno == errno.EMLINK and os.path.islink(path)):
            raise OSError(
                errno.ELOOP,
                "is a symbolic link (refused: a run's files must be its own)",
                str(path),
            ) from None
        raise


def read_file_bytes(path: Path, limit: int = MAX_TEXT_BYTES) -> bytes:
    """The bytes of a regular file, opened without following a link (`open_nofollow`), read up
    to `limit` bytes: OSError for a link, a file that is not regular (a FIFO, a device) or one
    larger than `limit` (EFBIG), before more than `limit` bytes are read
    (`sim.reading.read_regular`)."""
    return read_regular(path, limit, open_nofollow)


def check_nesting(text: str, source: str, error=None) -> None:
    """`error` (RunError by default) naming `source` when `text` nests deeper than MAX_NESTING."""
    d = nesting_depth(text)
    if d > MAX_NESTING:
        raise (error or RunError)(f"{source}: nested {d} levels deep (at most {MAX_NESTING})")


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def check_output_path(path: Path, what: str = "--out") -> Path:
    """`path` as an output file, refused (RunError) when something other than a regular file is
    there: a symbolic link (never written through or replaced), a directory, a device node such as
    /dev/null, a FIFO or a socket; also when its folder does not exist."""
    path = Path(path)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise RunError(f"{what} {path}: {os_error_text(e)}") from None
    if st is not None:
        if stat.S_ISLNK(st.st_mode):
            raise RunError(f"{what} {path} is a symbolic link; give the path of a regular file")
        if stat.S_ISDIR(st.st_mode):
            raise RunError(f"{what} {path} is a directory; give a file name")
        if not stat.S_ISREG(st.st_mode):
            raise RunError(
                f"{what} {path} is not a regular file (a device, FIFO or socket); give a file path"
            )
    if not path.parent.is_dir():
        raise RunError(f"{what} {path}: the folder {path.parent} does not exist")
    return path


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write a file so that readers see the old or the new content, never a partial one: the
    bytes go to a temporary `.NAME.xxxxxxxx` beside it (mode 0666 less the umask, as a plain
    open would make it), are synced, and the temporary file is renamed over `path`. A failed
    write (a full disk) removes the temporary file and leaves `path` as it was; one that a kill
    interrupts leaves the temporary file, which `clean_temporary_files` removes."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        try:
            os.fchmod(fd, 0o666 & ~current_umask())
            _write_all(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)  # replaces a link at `path`, never writes through it
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    interrupt_point(path.name)


_TEMP_NAME = re.compile(r"^\.(?P<target>.+)\.[A-Za-z0-9_]{8}$")


def clean_temporary_files(run_dir: Path, targets: re.Pattern | None = None) -> list[Path]:
    """Remove the temporary files that killed `atomic_write_bytes` calls left in `run_dir` (for
    a file of `ATOMIC_FILES`, one whose name `targets` matches, or one that exists); returns what
    was removed. Call it only while holding the directory's lock, so that no live write loses
    its temporary file."""
    run_dir = Path(run_dir)
    removed = []
    try:
        entries = list(os.scandir(run_dir))
    except OSError:
        return removed
    for entry in entries:
        m = _TEMP_NAME.match(entry.name)
        if not m or not entry.is_file(follow_symlinks=False):
            continue
        target = m.group("target")
        if (
            target in ATOMIC_FILES
            or (targets is not None and targets.match(target))
            or (run_dir / target).exists()
        ):
            try:
                os.unlink(entry.path)
                removed.append(Path(entry.path))
            except FileNotFoundError:
                pass
    return removed


def repair_teams(run_dir: Path) -> int:
    """Set aside a cut-off last line of teams.jsonl (a kill or a full disk mid-append): the
    bytes after its last newline are appended, with a newline, to teams.jsonl.partial and the
    file is truncated to its last complete line, so that the next record starts a line of its
    own. Returns the number of bytes set aside (0: the file was whole)."""
    path = Path(run_dir) / TEAMS_FILE
    if not path.exists() and not path.is_symlink():
        return 0
    with os.fdopen(open_nofollow(path, os.O_RDWR), "rb+") as f:
        size = f.seek(0, os.SEEK_END)
        if size == 0:
            return 0
        f.seek(size - 1)
        if f.read(1) == b"\n":
            return 0
        cut, pos = 0, size
        while pos > 0:  # the last newline, read backwards
            step = min(pos, 1 << 16)
            pos -= step
            f.seek(pos)
            i = f.read(step).rfind(b"\n")
            if i >= 0:
                cut = pos + i + 1
                break
        f.seek(cut)
        tail = f.read()
        fd = open_nofollow(str(path) + PARTIAL_SUFFIX, os.O_WRONLY | os.O_APPEND | os.O_CREAT)
        try:
            _write_all(fd, tail + b"\n")
            os.fsync(fd)
        finally:
            os.close(fd)
        f.truncate(cut)
        f.flush()
        os.fsync(f.fileno())
    return len(tail)


def append_line(path: Path, line: str) -> None:
    """Append one line to a file (one os.write per chunk; no buffering in Python); a link at
    `path` is refused (`open_nofollow`)."""
    fd = open_nofollow(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT)
    try:
        _write_all(fd, (line + "\n").encode("utf-8"))
    finally:
        os.close(fd)
    interrupt_point(Path(path).name)


def trim_teams(run_dir: Path, generation: int) -> int:
    """Drop the records of teams.jsonl of generations >= `generation` (those a resume from a
    checkpoint of `generation` computes again), so that the file keeps one record per
    generation; the file is rewritten atomically, and only when something is dropped. Returns
    the number of records dropped."""
    path = Path(run_dir) / TEAMS_FILE
    if not path.exists() and not path.is_symlink():
        return 0
    data = read_file_bytes(path, MAX_RECORD_BYTES)
    keep, dropped = [], 0
    for line in data.splitlines(keepends=True):
        try:
            rec = (
                json.loads(line)
                if nesting_depth(line.decode("utf-8", "replace")) <= MAX_NESTING
                else None
            )
            g = rec.get("generation") if isinstance(rec, dict) else None
        except (ValueError, RecursionError):
            g = None
        if isinstance(g, int) and not isinstance(g, bool) and g >= generation:
            dropped += 1
            continue
        keep.append(line)
    if dropped:
        atomic_write_bytes(path, b"".join(keep))
    return dropped


def prepare_run_dir(run_dir: Path) -> None:
    """Before a run starts or resumes in `run_dir` (holding its lock): remove the temporary
    files of killed writes and set aside a cut-off last line of teams.jsonl."""
    clean_temporary_files(run_dir)
    snapshots = Path(run_dir) / SNAPSHOT_DIR
    if snapshots.is_dir() and not snapshots.is_symlink():
        clean_temporary_files(snapshots, re.compile(r"^generation-\d+\.pt$"))
    repair_teams(run_dir)


# ------------------------------------------------------------------ reading run files
def read_text(path: Path, limit: int = MAX_TEXT_BYTES) -> str:
    """The UTF-8 text of a run file (a byte-order mark is dropped), read without following a
    link and up to `limit` bytes (`read_file_bytes`); RunError naming the file when it cannot be
    read, is a link or too large, or is not UTF-8."""
    path = Path(path)
    try:
        data = read_file_bytes(path, limit)
    except OSError as e:
        raise RunError(f"{path} cannot be read ({e.strerror or type(e).__name__})") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise RunError(
            f"{path} is not UTF-8 text (byte 0x{data[e.start]:02x} at offset {e.start})"
        ) from None


def os_error_text(e: OSError) -> str:
    """'No space left on device: runs/x/checkpoint.pt' for an OSError (what and where)."""
    what = e.strerror or str(e) or type(e).__name__
    return f"{what}: {e.filename}" if e.filename else what


def run_dir_name(cfg: SwarmCoDeConfig, when: float | None = None) -> str:
    """SCENARIO[__bBUDGET][__OBJECTIVE]__SEED__TIME: what tells runs apart, e.g.
    'four-niche__0__20261201-223000', 'budget__b4000__roi__2__20261201-223000' (the budget
    when one is set, the objective when it is not the default)."""
    parts = [Path(cfg.scenario).stem]
    if cfg.budget is not None:
        parts.append(f"b{cfg.budget:g}")
    if cfg.objective != SwarmCoDeConfig.objective:
        parts.append(cfg.objective)
    parts += [str(cfg.seed), time.strftime("%Y%m%d-%H%M%S", time.localtime(when))]
    return "__".join(parts)


#: The most characters of a parent's name kept in a branch's (a branch of a branch of ... stays
#: a valid file name).
MAX_PARENT_NAME = 150


def branch_dir_name(parent: Path, generation: int, when: float | None = None) -> str:
    """PARENT__branch-gG__TIME: a run branched from the run directory `parent` at its snapshot
    of generation G (`--from PARENT@G`), e.g. 'four-niche__0__20261201-223000__branch-g200__
    20261205-101500' (without the break): it sorts beside its parent and says it is a branch."""
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(when))
    return f"{Path(parent).name[:MAX_PARENT_NAME]}__branch-g{int(generation)}__{stamp}"


def new_run_dir(logdir: Path, cfg: SwarmCoDeConfig, branch=None) -> Path:
    """A new, empty run directory under `logdir`, named `run_dir_name` (`branch_dir_name` for a
    `branch`, a `checkpoints.Branch`: its parent's name and generation), with -1, -2, ... added
    when that exists. Each candidate is made with one mkdir that fails if it exists, so runs
    started at the same second (threads or processes) never share a directory."""
    logdir = Path(logdir)
    logdir.mkdir(parents=True, exist_ok=True)
    base = (
        run_dir_name(cfg) if branch is None else branch_dir_name(branch.run_dir, branch.generation)
    )
    i = 0
    while True:
        d = logdir / (base if i == 0 else f"{base}-{i}")
        try:
            d.mkdir()
            return d
        except FileExistsError:
            i += 1


#: The files of a run directory (each must be the run's own file, never a link).
RUN_FILES = (
    CONFIG_FILE,
    CHECKPOINT_FILE,
    SUMMARY_FILE,
    TEAMS_FILE,
    TEAMS_FILE + PARTIAL_SUFFIX,
    SCENARIO_COPY,
    HARDWARE_COPY,
    LOCK_FILE,
    METRICS_FILE,
    REPLAY_FILE,
)


def refuse_links(run_dir: Path) -> None:
    """RunError naming the first file of `RUN_FILES` in `run_dir` that is a symbolic link: a
    run reads and writes only its own files, never what a link planted in it points to."""
    for name in RUN_FILES:
        path = Path(run_dir) / name
        if path.is_symlink():
            raise RunError(
                f"{path} is a symbolic link; a run's files must be its own (remove "
                "the link, or put the file itself there)"
            )


def own_folder(folder: Path, what: str, make: bool = False) -> Path:
    """`folder`, a run's folder of `what` ("snapshots", "checkpoints"), made when `make`;
    RunError when it is a link or not a folder (a run reads and writes only its own files)."""
    if folder.is_symlink():
        raise RunError(f"{folder} is a symbolic link; a run's {what} must be its own")
    if folder.exists() and not folder.is_dir():
        raise RunError(f"{folder} is not a folder")
    if make:
        folder.mkdir(exist_ok=True)
    return folder


def numbered_files(folder: Path, name: re.Pattern, files_only: bool = False) -> dict[int, Path]:
    """number -> the entry of `folder` whose name `name` matches (its first group the number),
    in order ({} without the folder); `files_only`: regular files only, no links."""
    if not folder.is_dir():
        return {}
    found = {}
    for entry in os.scandir(folder):
        m = name.match(entry.name)
        if m and (not files_only or entry.is_file(follow_symlinks=False)):
            found[int(m.group(1))] = Path(entry.path)
    return dict(sorted(found.items()))
