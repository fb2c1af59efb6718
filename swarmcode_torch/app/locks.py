"""Locks: one live process per run (or sweep) directory."""

from __future__ import annotations

import errno
import os
import re
import socket
import time
from pathlib import Path

from .files import LOCK_FILE, RunError, _write_all, open_nofollow, read_file_bytes

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX
    fcntl = None


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

    def acquire(self) -> RunLock:
        info = f"pid={os.getpid()} host={socket.gethostname()} since={time.strftime('%Y-%m-%dT%H:%M:%S')}\n"
        while True:
            try:  # a link planted as the lock file is refused
                fd = open_nofollow(self.path, os.O_RDWR | os.O_CREAT)
            except OSError as e:
                if e.errno == errno.ELOOP:
                    raise RunError(
                        f"{self.path} is a symbolic link; a run's lock must be its "
                        "own file (remove the link)"
                    ) from None
                raise
            try:
                if fcntl is not None:
                    try:
                        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    except OSError as e:
                        if e.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                            raise
                        raise RunError(
                            f"{self.dir} is in use by a live run ({self._holder()}, "
                            f"{self.path}); wait for it to finish or stop it first"
                        ) from None
                elif self._live_holder():  # pragma: no cover - no flock: trust the pid
                    raise RunError(
                        f"{self.dir} is in use by a live run ({self._holder()}, "
                        f"{self.path}); wait for it to finish or stop it first"
                    )
                try:  # the file may have been released (removed) meanwhile
                    same = os.stat(self.path).st_ino == os.fstat(fd).st_ino
                except FileNotFoundError:
                    same = False
                if not same:
                    os.close(fd)
                    continue
                os.ftruncate(fd, 0)  # a dead holder's pid is overwritten: taken over
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

    def __enter__(self) -> RunLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
