"""Run directories: config.toml, atomic checkpoints, and the generation loop with reporters.

A run directory holds everything the run needs to continue or be replayed: its config, its
checkpoint, the scenario TOML it ran on (scenario.toml) and the hardware catalog as it was read
(hardware.toml). A live run holds run.lock (its pid and host) so that no second process writes
into it. docs/RELIABILITY.md lists what the files promise and the tests that show it.
"""

from __future__ import annotations

import errno
import hashlib
import io
import json
import math
import os
import pickle
import re
import signal
import socket
import sys
import threading
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Protocol

import torch

from ..coevo.config import SettingError, SwarmCoDeConfig, with_overrides
from ..coevo.evolve import Evolution, GenerationResult
from . import records
from .settings import setting_message
from ..sim.hardware import (MAX_NESTING, Catalog, CatalogError, nesting_depth, catalog_toml_lines, default_catalog,
                            default_catalog_bytes, parse_catalog)
from ..sim.bt import NUM_OPCODES
from ..sim.scenario import Scenario, load_scenario, parse_scenario

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX
    fcntl = None

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

CONFIG_FILE = "config.toml"
CHECKPOINT_FILE = "checkpoint.pt"
SUMMARY_FILE = "summary.json"
TEAMS_FILE = "teams.jsonl"
PARTIAL_SUFFIX = ".partial"             # teams.jsonl.partial: cut-off lines set aside on resume
SCENARIO_COPY = "scenario.toml"         # the scenario file the run ran on, as read
HARDWARE_COPY = "hardware.toml"         # the hardware catalog the run ran with, as read
LOCK_FILE = "run.lock"                  # held by the live run: "pid=... host=..."
SWEEP_LOCK_FILE = "sweep.lock"          # held by a live sweep in its --out directory
METRICS_FILE = "metrics.csv"            # every scalar of every generation (reporting.CsvReporter)
REPLAY_FILE = "team.gif"                # the default output of `replay`
#: A sweep's outputs in its --out directory (sweep.write_outputs).
TABLE_MD, TABLE_CSV, BUDGET_PLOT = "table.md", "table.csv", "budget.png"
#: Files of a run directory written with `atomic_write_bytes`; a temporary `.NAME.xxxxxxxx` of
#: one of them (or of any file that exists) left by a killed write is removed on start.
ATOMIC_FILES = (CONFIG_FILE, CHECKPOINT_FILE, SUMMARY_FILE, SCENARIO_COPY, HARDWARE_COPY,
                METRICS_FILE, TEAMS_FILE, REPLAY_FILE, TABLE_MD, TABLE_CSV)
#: The most bytes read from a text file of a run or a scenario (config.toml, scenario.toml,
#: hardware.toml, summary.json; a scenario file and the catalog it names): far above any real
#: one, far below what would exhaust memory.
MAX_TEXT_BYTES = 16 * 2 ** 20
#: The most bytes read from teams.jsonl and metrics.csv (one record a generation).
MAX_RECORD_BYTES = 2 * 2 ** 30

#: The memory assumed when the machine's cannot be read.
FALLBACK_MEMORY = 64 * 2 ** 30


class RunError(ValueError):
    """A run directory, config or checkpoint that cannot be used (one-line message)."""


class Reporter(Protocol):
    def on_start(self, ev: Evolution) -> None: ...
    def on_generation(self, ev: Evolution, result: GenerationResult) -> None: ...
    def on_end(self, ev: Evolution) -> None: ...


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
    every such point (tests/test_reliability.py, the interrupt sweep)."""


@contextmanager
def deferred_signals(deliver: bool = True) -> Iterator[list[int]]:
    """Within the block Ctrl-C (SIGINT) and SIGTERM are held, not acted on: a step that must
    not be split (a generation's records and its checkpoint; the checkpoint written on an
    interrupt) completes, then the first held signal is delivered to the handler that was in
    place (Ctrl-C's KeyboardInterrupt, the CLI's SIGTERM handler, or the default action). Off
    the main thread signals cannot be handled and the block runs as it is. `deliver=False`:
    held signals are dropped (a second Ctrl-C while a stopping run writes its checkpoint or
    closes its files: the stop is under way). Yields the list of held signal numbers."""
    held: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield held
        return

    def hold(signum, frame):
        held.append(signum)

    previous = {}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, hold)
    except (ValueError, OSError):          # pragma: no cover - no signals here
        for sig, h in previous.items():
            signal.signal(sig, h)
        yield held
        return
    failed = True
    try:
        yield held
        failed = False
    finally:
        for sig, h in previous.items():
            signal.signal(sig, h if h is not None else signal.SIG_DFL)
        if held and deliver and not failed:  # an error in the block is reported, not replaced
            sig = held[0]
            h = previous.get(sig)
            if callable(h):
                h(sig, None)
            elif h != signal.SIG_IGN:
                signal.raise_signal(sig)   # the default action, as if it arrived now


def open_nofollow(path: Path, flags: int, mode: int = 0o666) -> int:
    """os.open that never follows a symbolic link at `path` (O_NOFOLLOW): a run's files are its
    own, and a link planted in a run directory must not make a run read or write elsewhere.
    OSError (ELOOP) for a link, reported as "is a symbolic link"."""
    try:
        return os.open(path, flags | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0),
                       mode)
    except OSError as e:
        if e.errno == errno.ELOOP or (e.errno == errno.EMLINK and os.path.islink(path)):
            raise OSError(errno.ELOOP, "is a symbolic link (refused: a run's files must be "
                          "its own)", str(path)) from None
        raise


def read_file_bytes(path: Path, limit: int = MAX_TEXT_BYTES) -> bytes:
    """The bytes of a regular file, opened without following a link (`open_nofollow`), read up
    to `limit` bytes: OSError for a link, a file that is not regular (a FIFO, a device) or one
    larger than `limit` (EFBIG), before more than `limit` bytes are read."""
    fd = open_nofollow(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    try:
        st = os.fstat(fd)
        import stat as _stat
        if not _stat.S_ISREG(st.st_mode):
            raise OSError(errno.EINVAL, "not a regular file", str(path))
        if st.st_size > limit:
            raise OSError(errno.EFBIG, f"file too large ({st.st_size} bytes, at most {limit})",
                          str(path))
        chunks, total = [], 0
        while True:
            b = os.read(fd, min(1 << 20, limit + 1 - total))
            if not b:
                break
            chunks.append(b)
            total += len(b)
            if total > limit:
                raise OSError(errno.EFBIG, f"file too large (more than {limit} bytes)",
                              str(path))
        return b"".join(chunks)
    finally:
        os.close(fd)


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
        os.replace(tmp, path)              # replaces a link at `path`, never writes through it
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    interrupt_point(path.name)


_TEMP_NAME = re.compile(r"^\.(?P<target>.+)\.[A-Za-z0-9_]{8}$")


def clean_temporary_files(run_dir: Path) -> list[Path]:
    """Remove the temporary files that killed `atomic_write_bytes` calls left in `run_dir` (for
    a file of `ATOMIC_FILES` or one that exists); returns what was removed. Call it only while
    holding the directory's lock, so that no live write loses its temporary file."""
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
        if target in ATOMIC_FILES or (run_dir / target).exists():
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
        while pos > 0:                                 # the last newline, read backwards
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
            rec = json.loads(line) if nesting_depth(line.decode("utf-8", "replace")) \
                <= MAX_NESTING else None
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
        raise RunError(f"{path} is not UTF-8 text (byte 0x{data[e.start]:02x} at offset "
                       f"{e.start})") from None


def os_error_text(e: OSError) -> str:
    """'No space left on device: runs/x/checkpoint.pt' for an OSError (what and where)."""
    what = e.strerror or str(e) or type(e).__name__
    return f"{what}: {e.filename}" if e.filename else what


# ------------------------------------------------------------------ locks
class RunLock:
    """An exclusive lock on a run (or sweep) directory for one process: the file `name` in it
    holds the holder's pid and host. The lock itself is an advisory `flock` on that file, which
    the kernel drops when the process dies, so a lock file left by a killed run (a dead pid) is
    taken over; a live holder makes `acquire` raise RunError. `release` (also on leaving a `with`
    block, on an error, Ctrl-C or SIGTERM turned into KeyboardInterrupt) removes the file."""

    def __init__(self, directory: Path, name: str = LOCK_FILE):
        self.dir = Path(directory)
        self.path = self.dir / name
        self.fd: int | None = None

    def _holder(self) -> str:
        try:
            text = read_file_bytes(self.path, 4096).decode("utf-8", "replace").strip()
        except OSError:
            text = ""
        return text or "an unknown process"

    def acquire(self) -> "RunLock":
        info = f"pid={os.getpid()} host={socket.gethostname()} since={time.strftime('%Y-%m-%dT%H:%M:%S')}\n"
        while True:
            try:                           # a link planted as the lock file is refused
                fd = open_nofollow(self.path, os.O_RDWR | os.O_CREAT)
            except OSError as e:
                if e.errno == errno.ELOOP:
                    raise RunError(f"{self.path} is a symbolic link; a run's lock must be its "
                                   "own file (remove the link)") from None
                raise
            try:
                if fcntl is not None:
                    try:
                        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    except OSError as e:
                        if e.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                            raise
                        raise RunError(f"{self.dir} is in use by a live run ({self._holder()}, "
                                       f"{self.path}); wait for it to finish or stop it first") \
                            from None
                elif self._live_holder():  # pragma: no cover - no flock: trust the pid
                    raise RunError(f"{self.dir} is in use by a live run ({self._holder()}, "
                                   f"{self.path}); wait for it to finish or stop it first")
                try:                       # the file may have been released (removed) meanwhile
                    same = os.stat(self.path).st_ino == os.fstat(fd).st_ino
                except FileNotFoundError:
                    same = False
                if not same:
                    os.close(fd)
                    continue
                os.ftruncate(fd, 0)        # a dead holder's pid is overwritten: taken over
                _write_all(fd, info.encode())
            except BaseException:
                os.close(fd)
                raise
            self.fd = fd
            return self

    def _live_holder(self) -> bool:  # pragma: no cover - used only without fcntl
        m = re.search(r"pid=(\d+) host=(\S+)", self._holder())
        if not m or m.group(2) != socket.gethostname():
            return bool(m)
        try:
            os.kill(int(m.group(1)), 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return int(m.group(1)) != os.getpid()

    def release(self) -> None:
        if self.fd is None:
            return
        try:
            if os.stat(self.path).st_ino == os.fstat(self.fd).st_ino:
                os.unlink(self.path)
        except OSError:
            pass
        finally:
            os.close(self.fd)
            self.fd = None

    def __enter__(self) -> "RunLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


# ------------------------------------------------------------------ config.toml
def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    return json.dumps(str(v))


def config_to_toml(cfg: SwarmCoDeConfig, software: dict | None = None) -> str:
    """config.toml: every set key of `cfg`; `software` (`records.software`), what wrote it, goes
    into a comment line (a config file holds settings only)."""
    lines = ["# swarmcode-torch run configuration (re-run with: swarmcode-torch evolve --resume DIR)"]
    if software:
        lines.append("# written by " + ", ".join(f"{k} {v}" for k, v in software.items()
                                                  if v is not None))
    defaults = SwarmCoDeConfig().to_dict()
    for k, v in cfg.to_dict().items():
        if v is not None:
            lines.append(f"{k} = {_toml_value(v)}")
        elif defaults.get(k) is not None:
            # TOML has no null: a key unset where its default is set (quota_size_exponent)
            # is written "none", which reading a config turns back into None
            lines.append(f'{k} = "none"')
    return "\n".join(lines) + "\n"


def write_config(run_dir: Path, cfg: SwarmCoDeConfig) -> None:
    atomic_write_bytes(Path(run_dir) / CONFIG_FILE,
                       config_to_toml(cfg, records.software(cfg.device)).encode())


#: The names of config keys in messages about a config file: the keys themselves.
# ------------------------------------------------------------------ config migrations
#: Settings of configs saved before `quota_basis` and the mutation steps were config keys.
LEGACY_DEFAULTS = {"quota_basis": "mean", "hw_sigma": 0.1, "social_sigma": 0.1,
                   "p_categorical": 0.1}

#: Episode lengths of built-in scenarios whose default has changed since runs began pinning
#: theirs in config.toml; a saved config without `ticks` ran with these.
LEGACY_EPISODE_TICKS = {"one-niche": 250, "two-niche": 250, "four-niche": 250}


def migrate_config(d: Any, keep_retired: bool = False) -> Any:
    """A config table written by any version -> this version's keys, with the values the run
    was made with for every setting added since (the one place config migrations live), less
    the retired settings (`drop_retired_settings`; kept with `keep_retired`). Anything but a
    table is returned as it is (`SwarmCoDeConfig.from_dict` refuses it)."""
    if not isinstance(d, dict):
        return d
    d = {k: (None if v == "none" else v) for k, v in d.items()}
    if "w_tag" in d:
        # written since 0.7, which writes every key and none of the retired ones
        return d if keep_retired else drop_retired_settings(d)
    if "quota_basis" not in d:
        # written before these settings existed: keep the run's original algorithm
        d = {**LEGACY_DEFAULTS, **d}
    if "p_tag_flip" not in d:
        # written before the tag flip rate was a setting: it was one bit in L per child
        tag_length = d.get("tag_length", SwarmCoDeConfig.tag_length)
        d["p_tag_flip"] = 1.0 / int(tag_length) if isinstance(tag_length, int) else None
    if "min_share" not in d:
        d["min_share"] = 0.0     # written before the quota threshold existed
    # written before the paper-text fixes of d_hw and the tree mutation: the old behaviour
    d.setdefault("d_hw_tiers", True)
    d.setdefault("bt_point_on_nodes", False)
    d.setdefault("bt_mutation_rate", 1.0)
    d.setdefault("p_gene_mutation", 1.0)
    if "partners_per_niche" not in d:
        # written before 0.4: every species was a partner, and quotas were as quota_basis says
        # unless a quota_size_exponent was set (0.3.3)
        d["partners_per_niche"] = "all"
        d.setdefault("quota_size_exponent", None)
    # written before 0.5, which writes p_effector always ("none" unset): it was unset unless
    # the config names it
    d.setdefault("p_effector", None)
    # written before 0.6: every partner re-filled a focal's slots, and there were no presets
    d.setdefault("baseline_refill", "any")
    d.setdefault("partner_admission", "open")
    d.setdefault("preset", None)
    if d.get("ticks") is None and d.get("scenario") in LEGACY_EPISODE_TICKS:
        # written before runs pinned their episode length: the scenario's length of that time
        d["ticks"] = LEGACY_EPISODE_TICKS[d["scenario"]]
    return d if keep_retired else drop_retired_settings(d)


# ------------------------------------------------------------------ retired settings
#: Settings this version no longer has: key -> (the values that run as this version does, the
#: last version that ran the setting). Rejected experiments, and settings that kept behaviour
#: from before 0.2 for old runs; their results are in the research notes.
RETIRED_SETTINGS: dict[str, tuple[tuple[Any, ...], str]] = {
    "gate_margin": ((0, 0.0), "0.6.0"),
    "quota_inertia": ((0, 0.0), "0.6.0"),
    "effector_flip": (("gene",), "0.6.0"),
    "merge_species": ((False,), "0.6.0"),
    "evaluated_partners": ((False,), "0.6.0"),
    "baseline_refill": (("any",), "0.6.0"),
    "d_hw_tiers": ((False,), "0.6.0"),
    "bt_point_on_nodes": ((True,), "0.6.0"),
    # with quota_size_exponent set, quota_basis changed nothing (`retired_setting`)
    "quota_basis": (("sum",), "0.6.0"),
}
#: Retired values of settings this version keeps: (key, value) -> the last version that ran it.
RETIRED_VALUES = {("partner_admission", "gate"): "0.6.0"}


def retired_setting(d: dict) -> str | None:
    """For a migrated config table (`migrate_config` before it drops the retired keys): a
    one-line message naming the first setting whose value this version cannot run (a retired
    key at a value other than one that runs as this version does, or a retired value), with
    the last version that ran it; None if this version runs the config as it was run."""
    for key, (same, last) in RETIRED_SETTINGS.items():
        if key not in d:
            continue
        v = d[key]
        if key == "quota_basis" and d.get("quota_size_exponent") is not None:
            continue               # the exponent set the quotas
        if not any(v == ok and type(v) is type(ok) for ok in same):
            return (f"{key} = {v!r} is a retired setting that this version cannot run (last "
                    f"run by swarmcode-torch {last})")
    return retired_value(d)


def retired_value(d: dict) -> str | None:
    """A one-line message naming the first setting of a config table at a retired value
    (`RETIRED_VALUES`), which this version can neither run nor read; None if there is none."""
    for (key, value), last in RETIRED_VALUES.items():
        if d.get(key) == value:
            return (f"{key} = {value!r} is retired; this version cannot run it (last run by "
                    f"swarmcode-torch {last})")
    return None


def drop_retired_settings(d: dict) -> dict:
    """A migrated config table without the retired settings (`RETIRED_SETTINGS`): what a run
    directory records of them is read, not run (`retired_setting` tells a resume)."""
    return {k: v for k, v in d.items() if k not in RETIRED_SETTINGS}


def check_runnable(d: Any, source: str) -> None:
    """RunError naming the setting, for a config table (of any version) that holds a retired
    setting at a value this version cannot run (`retired_setting`)."""
    if not isinstance(d, dict):
        return
    problem = retired_setting(migrate_config(d, keep_retired=True))
    if problem:
        raise RunError(f"{source}: {problem}")


def config_from_dict(d: Any, source: str) -> SwarmCoDeConfig:
    """A validated config from a parsed table (config.toml, a checkpoint's "config") of any
    version; RunError naming `source` and the key for anything malformed or out of range."""
    problem = retired_value(d) if isinstance(d, dict) else None
    if problem:
        raise RunError(f"{source}: {problem}")
    try:
        cfg = SwarmCoDeConfig.from_dict(migrate_config(d))
        # a run made on a larger machine can still be inspected and replayed here; a resume
        # checks the memory it needs (`resume`)
        cfg.validate()
    except (TypeError, ValueError) as e:
        raise RunError(f"{source}: malformed config ({e})") from None
    return cfg


def read_config(run_dir: Path) -> SwarmCoDeConfig:
    """The config of a run directory, every value checked (`SwarmCoDeConfig.validate`)."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise RunError(f"{run_dir} is not a run directory (no {CONFIG_FILE})")
    text = read_text(path)
    check_nesting(text, str(path))
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise RunError(f"{path}: malformed config ({e})") from None
    except RecursionError:
        raise RunError(f"{path}: nested too deeply") from None
    missing = [k for k in CONFIG_REQUIRED if k not in d]
    if missing:
        # an empty or cut config would read as the defaults: another run than the one made
        raise RunError(f"{path}: {'empty' if not d else 'incomplete'} config (no "
                       f"{', '.join(missing)}); restore it from the run's checkpoint or backup")
    return config_from_dict(d, str(path))


#: Keys every config.toml a run has written holds (each version wrote them all).
CONFIG_REQUIRED = ("scenario", "generations", "population", "seed")


# ------------------------------------------------------------------ a run's own scenario
def hardware_bytes(hardware: Catalog | None = None) -> bytes:
    """What a run keeps as its hardware.toml: the installed catalog file as read
    (swarmcode_torch/data/hardware.toml) when the run uses it, else the run's scenario's own
    catalog written out as TOML (it parses back to the same catalog)."""
    if hardware is None or hardware == default_catalog():
        return default_catalog_bytes()
    head = ["# The hardware catalog of this run's scenario (its `hardware` key), as the run "
            "read it.",
            "# Tiers are listed 1, 2, 3. Units and the meaning of each field: data/hardware.toml."]
    return ("\n".join(head + catalog_toml_lines(hardware)) + "\n").encode("utf-8")


def write_run_files(run_dir: Path, cfg: SwarmCoDeConfig, scenario_data: bytes,
                    hardware: Catalog | None = None) -> None:
    """config.toml, and the copies that make a new run self-contained: scenario.toml (the bytes
    its scenario was read from) and hardware.toml (the catalog its robots are built from,
    `hardware_bytes`)."""
    run_dir = Path(run_dir)
    write_config(run_dir, cfg)
    atomic_write_bytes(run_dir / SCENARIO_COPY, scenario_data)
    atomic_write_bytes(run_dir / HARDWARE_COPY, hardware_bytes(hardware))


def run_scenario_source(run_dir: Path, cfg: SwarmCoDeConfig) -> str:
    """Where the scenario of a run is read from: its scenario.toml copy (an absolute path, so
    any working directory will do), or, in a run directory made before runs kept one, the
    config's scenario."""
    copy = Path(run_dir) / SCENARIO_COPY
    return str(copy.absolute()) if copy.is_file() or copy.is_symlink() else cfg.scenario


def run_catalog(run_dir: Path) -> Catalog | None:
    """The hardware catalog a run ran with: its hardware.toml copy (RunError when that cannot be
    read or is not a valid catalog), or None for a run made before runs kept one (it used the
    installed catalog)."""
    copy = Path(run_dir) / HARDWARE_COPY
    if not copy.is_file() and not copy.is_symlink():
        return None
    try:
        data = read_file_bytes(copy)
    except OSError as e:
        raise RunError(f"{copy}: cannot be read ({e.strerror or type(e).__name__})") from None
    try:
        return parse_catalog(data, str(copy))
    except CatalogError as e:
        raise RunError(str(e)) from None


def run_scenario(run_dir: Path, cfg: SwarmCoDeConfig) -> Scenario:
    """The scenario a run ran on (see `run_scenario_source`), its robots built from the run's
    own hardware.toml (`run_catalog`): whatever has become of the installed catalog or of the
    file the scenario named, a resumed or replayed run computes with the catalog it started
    with."""
    copy = Path(run_dir) / SCENARIO_COPY
    catalog = run_catalog(run_dir)
    if not copy.is_file() and not copy.is_symlink():
        return load_scenario(cfg.scenario, catalog)      # a run made before runs kept copies
    try:
        data = read_file_bytes(copy)                     # never through a link
    except OSError as e:
        raise RunError(f"{copy} cannot be read ({e.strerror or type(e).__name__})") from None
    return parse_scenario(data, str(copy.absolute()), copy.parent, catalog)


def config_differences(a: SwarmCoDeConfig, b: SwarmCoDeConfig, scenario: Scenario | None = None,
                       ignore: Iterable[str] = ("generations", "device")) -> list[str]:
    """The config keys in which `a` and `b` differ (except `ignore`); an unset swarm_size or
    ticks counts as the scenario's (what a run pins when it starts)."""
    da, db = a.to_dict(), b.to_dict()
    if scenario is not None:
        for d in (da, db):
            if d["swarm_size"] is None:
                d["swarm_size"] = scenario.num_robots
            if d["ticks"] is None:
                d["ticks"] = scenario.episode_ticks
    ignore = set(ignore)
    return sorted(k for k in da if k not in ignore and da[k] != db[k])


# ------------------------------------------------------------------ memory
def memory_limit(device: str = "auto") -> tuple[int, str]:
    """(bytes, what) of the memory a run's evaluation batch lives in: the total memory of the
    CUDA device it would run on, or this machine's physical memory; FALLBACK_MEMORY (64 GiB)
    when neither can be read."""
    try:
        if device != "cpu" and torch.cuda.is_available():
            idx = torch.device("cuda" if device == "auto" else device).index or 0
            if idx < torch.cuda.device_count():
                return torch.cuda.get_device_properties(idx).total_memory, f"cuda:{idx} memory"
        if device == "cpu" or not device.startswith("cuda"):
            n = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
            if n > 0:
                return n, "memory"
    except (ValueError, OSError, RuntimeError, AttributeError):
        pass
    return FALLBACK_MEMORY, "assumed memory (64 GiB)"


def estimate_bytes(cfg: SwarmCoDeConfig, scenario: Scenario | None = None) -> int:
    """A rough estimate of the memory one generation needs (a lower bound of the peak, close to
    the measured peak of a swarm1000 generation), in bytes:

    - the evaluation batch: E = 2 x population x trials environments of N robots (the swarm
      size; the scenario's robots; 1 when unknown), 16 x (16 + C + min(N, 500)) bytes a robot
      (state and constants, distances to the C grip points of the packages, contact pairs);
    - the layouts: population x trials environments of 32 candidate positions for each of the
      K packages (checked against the O obstacles) and each obstacle: 4 x 32 x (K (O + 4) + 2 O);
    - the start slots: 3 x 8 x N^2 bytes (pairwise distances of the N robots' slots);
    - the programs: population x (4 x 11,664 lookup-table entries + 16 x bt_length + tag_length).
    """
    from ..sim.bt import NUM_COMBOS

    P, T = cfg.population, cfg.trials
    if scenario is not None:
        N = cfg.swarm_size or scenario.num_robots
        C = sum(c.count * len(c.grips) for c in scenario.packages)
        K, O = scenario.num_packages, scenario.obstacle_count
    else:
        N, C, K, O = cfg.swarm_size or 1, 1, 1, 0
    envs = 2 * P * T
    batch = envs * N * 16 * (16 + C + min(N, 500))
    layouts = P * T * 4 * 32 * (K * (O + 4) + 2 * O)
    # the start slots: pairwise distances of the scenario's robots, three [N, N] float64
    # tensors at once (layout.spawn_slots: cdist, eye, their sum)
    M = max(N, scenario.num_robots if scenario is not None else 1)
    layouts += 3 * 8 * M * M
    programs = P * (4 * NUM_COMBOS + 16 * cfg.bt_length + cfg.tag_length)
    return batch + layouts + programs


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"):
        if n < 1024 or unit == "EiB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.3g} EiB"  # pragma: no cover


def check_memory(cfg: SwarmCoDeConfig, scenario: Scenario | None = None,
                 option_names: dict[str, str] | None = None) -> None:
    """ValueError, before anything is allocated, when `estimate_bytes` exceeds `memory_limit`:
    the message gives the estimate and the settings that size it, by their config keys
    (`population`, as the API takes them) or as `option_names` spells them (--population)."""
    need = estimate_bytes(cfg, scenario)
    limit, what = memory_limit(cfg.device if isinstance(cfg.device, str) else "auto")
    if need <= limit:
        return
    names = {"population": "population", "trials": "trials", "swarm_size": "swarm_size",
             **(option_names or {})}
    N = cfg.swarm_size or (scenario.num_robots if scenario is not None else 1)
    robots = f"{N} robots" if cfg.swarm_size or scenario is None else \
        f"{N} robots (num_robots of scenario {cfg.scenario})"
    raise ValueError(
        f"this run would need about {_size(need)} of memory, more than the {_size(limit)} of "
        f"{what}: {2 * cfg.population * cfg.trials} environments of {robots} a generation "
        f"(2 x population x trials) and the programs of {cfg.population} individuals of "
        f"bt_length {cfg.bt_length}; use a smaller {names['population']}, {names['trials']} or "
        f"{names['swarm_size']}")


def check_config(cfg: SwarmCoDeConfig, scenario: Scenario | None = None,
                 option_names: dict[str, str] | None = None) -> None:
    """Everything a run's config must pass before anything is made: its settings' types and
    ranges, then the memory its sizes need (so that sizes far too large are told what they
    would need), then the upper bounds that memory does not bound. ValueError, one line, that
    names a setting by its key or as `option_names` spells it (`settings.setting_message`)."""
    try:
        cfg.validate(bounds=False)
        check_memory(cfg, scenario, option_names)
        cfg.check_bounds()
    except SettingError as e:
        raise ValueError(setting_message(e, option_names)) from None


# ------------------------------------------------------------------ checkpoints
def copy_digests(run_dir: Path) -> dict[str, str]:
    """sha256 of the run's scenario.toml and hardware.toml copies (those it has): a checkpoint
    keeps them ("run_files"), so that a resume notices a copy edited since."""
    out = {}
    for name in (SCENARIO_COPY, HARDWARE_COPY):
        path = Path(run_dir) / name
        if path.is_file() and not path.is_symlink():
            out[name] = hashlib.sha256(read_file_bytes(path)).hexdigest()
    return out


def check_copies(run_dir: Path, d: dict) -> None:
    """RunError naming a scenario.toml or hardware.toml copy whose bytes are not those the
    checkpoint `d` recorded (edited since the run started; a checkpoint without "run_files",
    written before they were recorded, is not checked)."""
    saved = d.get("run_files")
    if not isinstance(saved, dict):
        return
    now = copy_digests(run_dir)
    for name in (SCENARIO_COPY, HARDWARE_COPY):
        if saved.get(name) != now.get(name):
            state = "is missing" if name not in now else "was changed"
            raise RunError(f"{Path(run_dir) / name} {state} since the run started (its sha256 "
                           f"is not the one {CHECKPOINT_FILE} recorded); the run computes with "
                           "its own copy: restore it, or start a new run")


def save_checkpoint(run_dir: Path, ev: Evolution) -> Path:
    buf = io.BytesIO()
    torch.save({**ev.state_dict(), "run_files": copy_digests(run_dir)}, buf)
    path = Path(run_dir) / CHECKPOINT_FILE
    atomic_write_bytes(path, buf.getvalue())
    return path


#: What a checkpoint may hold at the top level, and the type of each entry.
_CHECKPOINT_KEYS = {"version": int, "config": dict, "generation": int, "genome": dict,
                    "species_hint": torch.Tensor, "proto": (dict, type(None)),
                    "proto_ids": torch.Tensor, "next_species_id": int, "fitness": torch.Tensor,
                    "has_fitness": torch.Tensor, "rng_state": torch.Tensor,
                    "best": (dict, type(None)), "history": list}


def read_checkpoint(path: Path) -> dict:
    """The contents of a checkpoint file, unpickled with `torch.load(weights_only=True)`: only
    tensors, plain containers, numbers and strings are rebuilt, so no code in the file can run.
    RunError for a file that would call anything on loading, a damaged file, or one that is not a
    swarmcode-torch checkpoint."""
    path = Path(path)
    try:
        with os.fdopen(open_nofollow(path, os.O_RDONLY), "rb") as f:   # never through a link
            d = torch.load(f, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        if "weights only load failed" in str(e).lower() or "unsupported global" in str(e).lower():
            raise RunError(f"{path} was refused: loading it would run code (only tensors, "
                           "numbers, strings and plain containers are allowed)") from None
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
            raise RunError(f"{path} is damaged: {key!r} has the wrong type "
                           f"({type(d[key]).__name__})")
    return d


def load_checkpoint(run_dir: Path) -> dict:
    """The checkpoint of a run directory (see `read_checkpoint`)."""
    path = Path(run_dir) / CHECKPOINT_FILE
    if not path.is_file() and not path.is_symlink():
        raise RunError(f"{run_dir} has no {CHECKPOINT_FILE} to resume from")
    return read_checkpoint(path)


#: The files of a run directory (each must be the run's own file, never a link).
RUN_FILES = (CONFIG_FILE, CHECKPOINT_FILE, SUMMARY_FILE, TEAMS_FILE, TEAMS_FILE + PARTIAL_SUFFIX,
             SCENARIO_COPY, HARDWARE_COPY, LOCK_FILE, METRICS_FILE, REPLAY_FILE)


def refuse_links(run_dir: Path) -> None:
    """RunError naming the first file of `RUN_FILES` in `run_dir` that is a symbolic link: a
    run reads and writes only its own files, never what a link planted in it points to."""
    for name in RUN_FILES:
        path = Path(run_dir) / name
        if path.is_symlink():
            raise RunError(f"{path} is a symbolic link; a run's files must be its own (remove "
                           "the link, or put the file itself there)")


def load_run(run_dir: Path) -> tuple[SwarmCoDeConfig, dict, Scenario]:
    """The config, checkpoint and scenario of a run directory, checked against each other:
    config.toml must agree with the config saved in the checkpoint in every key but generations
    and device (RunError otherwise); the scenario is built with the run's own catalog."""
    run_dir = Path(run_dir)
    refuse_links(run_dir)
    cfg = read_config(run_dir)
    d = load_checkpoint(run_dir)
    scenario = run_scenario(run_dir, cfg)       # a damaged copy: the file and field named
    check_copies(run_dir, d)
    saved = config_from_dict(d["config"], f"{run_dir / CHECKPOINT_FILE} (its config)")
    diff = config_differences(cfg, saved, scenario)
    if diff:
        raise RunError(f"{run_dir / CONFIG_FILE} does not match the config saved in "
                       f"{CHECKPOINT_FILE} (differing keys: {', '.join(diff)}); restore "
                       f"{CONFIG_FILE} or start a new run")
    metrics = run_dir / METRICS_FILE
    if metrics.exists() or metrics.is_symlink():
        from .reporting import read_metrics_csv
        read_metrics_csv(metrics, raw=True)      # a header a resume would lose rows under
    return cfg, d, scenario


def resume(run_dir: Path, generations: int | None = None, device: str | None = None,
           loaded: tuple[SwarmCoDeConfig, dict, Scenario] | None = None,
           fitness=None) -> Evolution:
    """The run in `run_dir`, continued from its checkpoint with its saved config and its own
    copy of the scenario (`load_run`; `loaded` is what `load_run` returned, if it was called).
    `fitness`: the user fitness function of a run started with one (`api.evolve(fitness=)`),
    which a run directory records by name only; RunError without it, or with one for a run
    scored by the built-in fitness."""
    run_dir = Path(run_dir)
    cfg, d, scenario = loaded or load_run(run_dir)
    if cfg.fitness_function is not None and fitness is None:
        raise RunError(f"{run_dir} was scored by a custom fitness function "
                       f"({cfg.fitness_function}): resume it from Python with the same "
                       "function, swarmcode_torch.resume(run_dir, fitness=fn)")
    if cfg.fitness_function is None and fitness is not None:
        raise RunError(f"{run_dir} was scored by the built-in fitness; a resume cannot change "
                       "its fitness function (start a new run with fitness=fn)")
    check_runnable(d["config"], str(run_dir / CHECKPOINT_FILE))
    cfg = with_overrides(cfg, generations=generations, device=device)
    check_config(cfg, scenario)
    try:                           # the run keeps the scenario it names; it runs on its copy
        return Evolution.from_checkpoint(d, cfg, fitness, scenario, checked=True)
    except ValueError as e:
        raise RunError(f"{run_dir / CHECKPOINT_FILE} does not fit the run's config: {e}") from None
    except (KeyError, TypeError, RuntimeError, IndexError) as e:
        raise RunError(f"checkpoint in {run_dir} is incompatible ({type(e).__name__}: {e})") from None


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


def new_run_dir(logdir: Path, cfg: SwarmCoDeConfig) -> Path:
    """A new, empty run directory under `logdir`, named `run_dir_name`, with -1, -2, ... added
    when that exists. Each candidate is made with one mkdir that fails if it exists, so runs
    started at the same second (threads or processes) never share a directory."""
    logdir = Path(logdir)
    logdir.mkdir(parents=True, exist_ok=True)
    base = run_dir_name(cfg)
    i = 0
    while True:
        d = logdir / (base if i == 0 else f"{base}-{i}")
        try:
            d.mkdir()
            return d
        except FileExistsError:
            i += 1


# ------------------------------------------------------------------ summary.json
class SummaryReporter:
    """Rewrites summary.json (atomically) after every generation and appends the generation's
    best team to teams.jsonl (one JSON object per line). On a start or resume it prepares the
    directory (`prepare_run_dir`) and drops the records of teams.jsonl past the checkpoint the
    run continues from (`trim_teams`): those generations are computed again."""

    def __init__(self, run_dir: Path):
        self.run_dir = Path(run_dir)
        self.path = self.run_dir / SUMMARY_FILE
        self.teams = self.run_dir / TEAMS_FILE

    def on_start(self, ev: Evolution) -> None:
        prepare_run_dir(self.run_dir)       # no leftover temporary files, no cut-off line
        trim_teams(self.run_dir, ev.state.generation)

    def on_generation(self, ev: Evolution, result: GenerationResult) -> None:
        append_line(self.teams, json.dumps(records.team_line(result)))
        atomic_write_bytes(self.path, json.dumps(records.summary(ev, result), indent=2).encode())

    def on_end(self, ev: Evolution) -> None:
        pass


class CheckpointReporter:
    """Writes checkpoint.pt at the start of a new run (generation 0, so that a run stopped
    before its first periodic checkpoint can still be resumed), every `every` generations and
    after the last one (as part of that generation's step: `run` writes the records of a
    generation, then its checkpoint, with signals held). `saved` is the generation of the
    checkpoint on disk (None: none yet)."""

    def __init__(self, run_dir: Path, every: int):
        self.run_dir, self.every = Path(run_dir), max(1, every)
        self.saved: int | None = None

    def on_start(self, ev: Evolution) -> None:
        path = self.run_dir / CHECKPOINT_FILE
        if path.exists() or path.is_symlink():
            self.saved = ev.state.generation        # resumed from it
        else:
            self._save(ev)

    def _save(self, ev: Evolution) -> None:
        save_checkpoint(self.run_dir, ev)
        self.saved = ev.state.generation

    def save_state(self, ev: Evolution) -> None:
        """The checkpoint of `ev`'s state, unless the file holds that generation already."""
        if self.saved != ev.state.generation:
            self._save(ev)

    def on_generation(self, ev: Evolution, result: GenerationResult) -> None:
        if ev.state.generation % self.every == 0 or ev.done:
            self._save(ev)

    def on_end(self, ev: Evolution) -> None:
        self.save_state(ev)


# ------------------------------------------------------------------ run files read back
def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


#: The most robots the designs of a summary.json or teams.jsonl record may add up to (the
#: swarm_size bound); a replay also checks the memory its team needs (`analysis.replay_run`).
MAX_TEAM = 10_000_000


def check_designs(designs: Any, source: str) -> list[dict]:
    """The "designs" of a summary.json or teams.jsonl record, every field checked (RunError
    naming `source`, the design and the field)."""
    if not isinstance(designs, list) or not designs:
        raise RunError(f"{source}: designs: expected a non-empty list, got {designs!r:.60}")
    for i, d in enumerate(designs):
        w = f"{source}: designs[{i}]"
        if not isinstance(d, dict):
            raise RunError(f"{w}: expected a table, got {d!r:.60}")
        for key, ok, what in (
                ("count", lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 0,
                 "an integer >= 0"),
                ("species", lambda v: isinstance(v, int) and not isinstance(v, bool),
                 "an integer"),
                ("effector", lambda v: v in ("suction", "pincher"), "suction or pincher"),
                ("radius", lambda v: _is_number(v) and math.isfinite(v) and 0 < v <= 10,
                 "a radius in (0, 10] m"),
                ("chassis_tier", lambda v: v in (1, 2, 3) and not isinstance(v, bool), "1, 2 or 3"),
                ("battery_tier", lambda v: v in (1, 2, 3) and not isinstance(v, bool), "1, 2 or 3"),
                ("motor_tier", lambda v: v in (1, 2, 3) and not isinstance(v, bool), "1, 2 or 3"),
                ("torque_point", lambda v: _is_number(v) and math.isfinite(v), "a finite number"),
                ("battery_point", lambda v: _is_number(v) and math.isfinite(v), "a finite number"),
                ("dominance", lambda v: _is_number(v) and math.isfinite(v), "a finite number"),
                ("cost", lambda v: _is_number(v) and math.isfinite(v), "a finite number"),
                ("bt", lambda v: isinstance(v, list) and 0 < len(v) <= 4096 and all(
                    isinstance(x, int) and not isinstance(x, bool) and 0 <= x < NUM_OPCODES
                    for x in v),
                 f"a list of opcodes 0..{NUM_OPCODES - 1}")):
            if key not in d:
                raise RunError(f"{w}: missing {key!r}")
            if not ok(d[key]):
                raise RunError(f"{w}.{key}: expected {what}, got {d[key]!r:.60}")
    total = sum(d["count"] for d in designs)
    if total < 1:
        raise RunError(f"{source}: designs: the counts add up to no robot")
    if total > MAX_TEAM:
        raise RunError(f"{source}: designs: the counts add up to {total} robots, more than any "
                       f"run can have ({MAX_TEAM})")
    return designs


#: summary.json keys and whether each must be a number (None allowed: a non-finite value).
_SUMMARY_NUMBERS = ("best_fitness", "team_cost", "deliveries", "deliveries_individual",
                    "deliveries_collab", "energy_used", "num_species", "best_generation")


def read_summary(run_dir: Path, figures: bool = True) -> dict:
    """summary.json of a run, checked: a table whose designs are well-formed and (`figures`)
    whose figures are numbers (or null, where a value was not finite) and budget a number or
    null. A replay needs only the designs (figures=False)."""
    path = Path(run_dir) / SUMMARY_FILE
    if not path.is_file():
        raise RunError(f"{run_dir} has no {SUMMARY_FILE} (is it a run directory with a finished "
                       "generation?)")
    text = read_text(path)
    check_nesting(text, str(path))
    try:
        s = json.loads(text)
    except json.JSONDecodeError as e:
        raise RunError(f"{path}: malformed JSON ({e})") from None
    except RecursionError:
        raise RunError(f"{path}: nested too deeply") from None
    if not isinstance(s, dict):
        raise RunError(f"{path}: expected a JSON object")
    for key in _SUMMARY_NUMBERS if figures else ():
        if key not in s:
            raise RunError(f"{path}: missing {key!r}")
        v = s[key]
        if v is not None and not (_is_number(v) and math.isfinite(v)):
            raise RunError(f"{path}: {key}: expected a number, got {v!r:.60}")
    b = s.get("budget")
    if b is not None and not (_is_number(b) and math.isfinite(b)):
        raise RunError(f"{path}: budget: expected a number or null, got {b!r:.60}")
    check_designs(s.get("designs"), str(path))
    return s


def read_teams(run_dir: Path) -> dict[int, dict]:
    """generation -> its best-team record, from teams.jsonl (the last record of a generation
    wins after a resume; a line that is not a JSON object, cut short by an interruption, is
    skipped); {} when the run has no teams.jsonl."""
    path = Path(run_dir) / TEAMS_FILE
    out: dict[int, dict] = {}
    if not path.is_file() and not path.is_symlink():
        return out
    for line in read_text(path, MAX_RECORD_BYTES).splitlines():
        if nesting_depth(line) > MAX_NESTING:
            raise RunError(f"{path}: a record nested {nesting_depth(line)} levels deep (at most "
                           f"{MAX_NESTING})")
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line cut short by an interruption
        g = rec.get("generation") if isinstance(rec, dict) else None
        if isinstance(g, int) and not isinstance(g, bool):
            out[g] = rec
    return out


def generation_team(run_dir: Path, generation: int) -> dict:
    """The best team of one generation, from teams.jsonl (`read_teams`); its designs are
    checked (`check_designs`)."""
    path = Path(run_dir) / TEAMS_FILE
    if not path.is_file():
        raise RunError(f"{run_dir} has no {TEAMS_FILE}")
    found = read_teams(run_dir).get(generation)
    if found is None:
        raise RunError(f"{run_dir} has no record of generation {generation}")
    check_designs(found.get("designs"), f"{path} (generation {generation})")
    return found


def interrupt_of(e: BaseException) -> KeyboardInterrupt | None:
    """The KeyboardInterrupt (Ctrl-C, or SIGTERM turned into one) that `e` is or was raised
    from, else None: an interrupt that lands while a compiled extension module initialises
    (matplotlib's, imported for the first figure) reaches Python as an ImportError caused by it."""
    seen = 0
    while e is not None and seen < 16:
        if isinstance(e, KeyboardInterrupt):
            return e
        e, seen = e.__cause__ or e.__context__, seen + 1
    return None


def run(ev: Evolution, run_dir: Path, reporters: Iterable[Reporter],
        on_interrupt: Callable[[Path], None] | None = None) -> Evolution:
    """Run generations until the configured total.

    Each generation is one step that Ctrl-C or SIGTERM cannot split (`deferred_signals`): the
    reporters up to the last `CheckpointReporter` in `reporters` (the run's records: summary,
    teams.jsonl, metrics.csv, TensorBoard) write it, then its checkpoint is written when one is
    due; the reporters after it (a progress callback, a user's) run outside that step. On an
    interrupt (anywhere: while a generation computes, while the run starts, in the end-of-run
    work) the state whose records are all written is kept (a generation computed but not yet
    recorded is dropped: a resume computes it again, identically), its checkpoint written if the
    file does not hold it yet, and KeyboardInterrupt re-raised; the `CheckpointReporter`'s
    `saved` then names the generation the file holds."""
    reporters = list(reporters)
    marks = [i for i, r in enumerate(reporters) if isinstance(r, CheckpointReporter)]
    checkpoints = reporters[marks[-1]] if marks else None
    cut = marks[-1] + 1 if marks else len(reporters)
    step_reporters, after = reporters[:cut], reporters[cut:]
    recorded = ev.state                    # the last state whose records are all written
    try:
        with deferred_signals():
            for r in reporters:
                r.on_start(ev)
        while not ev.done:
            result = records.step(ev)
            interrupt_point("generation")
            with deferred_signals():
                for r in step_reporters:
                    r.on_generation(ev, result)
                recorded = ev.state
            for r in after:
                r.on_generation(ev, result)
        for r in reporters:
            r.on_end(ev)
    except BaseException as e:
        interrupt = interrupt_of(e)
        if interrupt is None:
            raise
        with deferred_signals(deliver=False):   # a second Ctrl-C cannot split this checkpoint
            ev.state = recorded
            if checkpoints is not None:
                checkpoints.save_state(ev)
                path = Path(run_dir) / CHECKPOINT_FILE
            else:
                path = save_checkpoint(run_dir, ev)
        if on_interrupt:
            on_interrupt(path)
        raise interrupt from None
    return ev
