"""One bounded reader of a regular file, for the scenario and catalog files (`sim.scenario`) and
a run's files (`app.files`): it refuses what is not a regular file and reads nothing past its
limit, so a FIFO, a device or a huge file can neither block nor exhaust memory. `tomllib` here is
the standard library's, or tomli's before Python 3.11."""

from __future__ import annotations

import errno
import os
import stat
import sys
from collections.abc import Callable
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["FileTooLargeError", "NotRegularFileError", "read_regular", "tomllib"]


class NotRegularFileError(OSError):
    """The path is not a regular file (a FIFO, a device, a folder)."""


class FileTooLargeError(OSError):
    """The file holds more than the limit; `size`: its size by stat, None when the size was
    found by reading past the limit."""

    size: int | None = None


def read_regular(
    path: Path, limit: int, open_fd: Callable[[Path, int], int] | None = None
) -> bytes:
    """The bytes of the regular file at `path`, at most `limit` of them, opened non-blocking by
    `open_fd(path, flags)` (os.open by default). NotRegularFileError, FileTooLargeError (before
    more than `limit` bytes are read) or the OSError of the open or a read."""
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0)
    fd = open_fd(path, flags) if open_fd is not None else os.open(path, flags)
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise NotRegularFileError(errno.EINVAL, "not a regular file", str(path))
        if st.st_size > limit:
            e = FileTooLargeError(
                errno.EFBIG, f"file too large ({st.st_size} bytes, at most {limit})", str(path)
            )
            e.size = st.st_size
            raise e
        chunks, total = [], 0
        while True:
            b = os.read(fd, min(1 << 20, limit + 1 - total))
            if not b:
                break
            chunks.append(b)
            total += len(b)
            if total > limit:
                raise FileTooLargeError(
                    errno.EFBIG, f"file too large (more than {limit} bytes)", str(path)
                )
        return b"".join(chunks)
    finally:
        os.close(fd)
