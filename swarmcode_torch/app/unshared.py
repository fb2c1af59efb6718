"""Runs of a Ray sweep on nodes that do not see the sweep directory.

The sweep's driver writes a mark, a random token, into its `--out` directory before it submits
the runs (`mark_storage`). A run's task reads it back (`sees_storage`): when it sees the same
token, `--out` is shared storage and the run writes its run directory there, as in one process.
When it does not (another node, whose disk has no such directory, or another directory at that
path), the run is made in a temporary directory of that node, from the files the driver sent
(those of a run to resume), and the task returns every file of its run directory
(`read_tree`); the driver writes them into `--out` (`write_tree`), where the sweep's table is
made from them. docs/DISTRIBUTED.md says what is shared and what not.
"""

from __future__ import annotations

import os
import secrets
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path, PurePosixPath

from .files import LOCK_FILE, atomic_write_bytes, read_file_bytes

#: The file in a sweep's --out that holds the driver's token for this sweep's runs.
STORAGE_MARK = ".storage-mark"
#: The most bytes of one file of a run directory sent between a node and the driver.
MAX_FILE_BYTES = 2 * 2**30


def mark_storage(out: Path) -> str:
    """Write a new random token into `out`/STORAGE_MARK; the token."""
    token = secrets.token_hex(16)
    atomic_write_bytes(Path(out) / STORAGE_MARK, token.encode())
    return token


def sees_storage(out: Path, token: str) -> bool:
    """Whether `out` here is the driver's sweep directory: its mark holds `token`."""
    try:
        return read_file_bytes(Path(out) / STORAGE_MARK, 1024).decode() == token
    except (OSError, UnicodeDecodeError):
        return False


def read_tree(root: Path) -> dict[str, bytes]:
    """Every regular file under `root` (not its lock, not what a link points to) by its path
    relative to `root` ('a/b.txt'); {} when `root` does not exist."""
    root = Path(root)
    files: dict[str, bytes] = {}
    if not root.is_dir():
        return files
    for dirpath, dirnames, filenames in os.walk(root):  # os.walk does not follow links
        for name in sorted(filenames):
            path = Path(dirpath) / name
            rel = path.relative_to(root).as_posix()
            if rel == LOCK_FILE or not stat.S_ISREG(os.lstat(path).st_mode):
                continue
            files[rel] = read_file_bytes(path, MAX_FILE_BYTES)
        dirnames.sort()
    return files


def write_tree(root: Path, files: dict[str, bytes]) -> None:
    """Write `files` (`read_tree`'s form) under `root`, each atomically, making folders as
    needed; ValueError for a path that would leave `root` (absolute, or with '..')."""
    root = Path(root)
    for rel in files:
        p = PurePosixPath(rel)
        if p.is_absolute() or not p.parts or any(part in ("", ".", "..") for part in p.parts):
            raise ValueError(f"refused a file path from a Ray worker: {rel!r}")
    for rel, data in files.items():
        path = root.joinpath(*PurePosixPath(rel).parts)
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, data)


def run_elsewhere(
    run_dir: Path, files: dict[str, bytes] | None, run: Callable[[Path], str | None]
) -> tuple[str | None, dict[str, bytes]]:
    """`run(local run directory)` in a temporary directory of this node named like `run_dir`,
    holding `files` first (a run to resume); (its error or None, every file of the run
    directory it left, even after an error: a checkpoint to resume from)."""
    with tempfile.TemporaryDirectory(prefix="swarmcode-run-") as tmp:
        local = Path(tmp) / Path(run_dir).name
        if files:
            local.mkdir()
            write_tree(local, files)
        error = run(local)
        return error, read_tree(local)
