"""The native extension (`csrc/tick.cpp`): built on first use, cached where it cannot hurt.

A leaf module (it imports nothing of the package), so that `bt` and `fused` can both use it.

Where the build lives and why it is safe:

- **Keyed by content.** The cache folder is ``BASE/swarmcode_tick-KEY`` where KEY is a SHA-256 of
  the source, the compiler flags, torch's version and the Python version. Two checkouts or venvs
  with different sources never rebuild each other's library; each builds its own once.
- **Private.** ``BASE`` is ``$SWARMCODE_EXTENSIONS_DIR``, else ``$TORCH_EXTENSIONS_DIR``, else
  ``~/.cache/swarmcode-torch/native``. The key folder is made 0700 and used only if the current
  user owns it and no one else can write to it; otherwise the Python tick runs.
- **Verified before it is loaded.** After a build the library's SHA-256 is written beside it
  (``library.sha256``); a cached library is loaded only if its bytes match. A truncated or
  replaced library (a killed build, a full disk, a planted file) is rebuilt, never mapped: a
  truncated shared object would end the process with SIGBUS.
- **A lock that cannot hang.** Builders take an exclusive ``flock`` on ``build.lock`` in the key
  folder. The kernel drops it when its holder dies (SIGKILL, the OOM killer), so a killed build
  leaves no lock behind; torch's own ``lock`` file, which a killed build does leave, is removed
  while the flock is held (no one else can be building then). A live holder is waited for at
  most ``SWARMCODE_BUILD_TIMEOUT`` seconds (default 600), then the Python tick runs.

Every failure (no compiler, a bad library, a folder that is not private, a lock held too long)
is returned as an exception by `build_error()`; callers fall back to the Python tick with one
warning. Nothing here waits forever or raises into a run.
"""

from __future__ import annotations

import fcntl
import hashlib
import importlib.machinery
import importlib.util
import os
import stat
import sys
import threading
import time
from pathlib import Path

import torch

SOURCE = Path(__file__).with_name("csrc") / "tick.cpp"
NAME = "swarmcode_tick"
CFLAGS = ("-O3", "-ffp-contract=off", "-fopenmp")
LDFLAGS = ("-fopenmp",)
HASH_FILE = "library.sha256"
LOCK_FILE = "build.lock"
#: The longest wait for another process's build of the same library (seconds).
DEFAULT_BUILD_TIMEOUT = 600.0

_lock = threading.Lock()
_module = None
_error: Exception | None = None


class NativeError(RuntimeError):
    """Why the native extension is not used (the Python tick runs instead)."""


def tick_choice() -> str:
    """``SWARMCODE_TICK``: 'fused' (default: the C++ tick on the CPU where it builds),
    'reference' (the Python tick, eager or torch.compile'd, as before) or 'triton' (the Python
    tick with its pair phases in Triton kernels, `triton_tick.TritonTicks`: on CUDA with triton
    installed, or on the CPU under ``TRITON_INTERPRET=1``; elsewhere the Python tick, saying
    so)."""
    v = os.environ.get("SWARMCODE_TICK", "fused").strip().lower() or "fused"
    if v not in ("fused", "reference", "triton"):
        raise ValueError(f"SWARMCODE_TICK must be 'fused', 'reference' or 'triton', got {v!r}")
    return v


def cache_base() -> Path:
    for var in ("SWARMCODE_EXTENSIONS_DIR", "TORCH_EXTENSIONS_DIR"):
        v = os.environ.get(var, "").strip()
        if v:
            return Path(v).expanduser()
    return Path.home() / ".cache" / "swarmcode-torch" / "native"


def build_key(source: bytes) -> str:
    h = hashlib.sha256()
    for part in (
        source,
        " ".join(CFLAGS + LDFLAGS).encode(),
        torch.__version__.encode(),
        sys.version.encode(),
        sys.platform.encode(),
    ):
        h.update(len(part).to_bytes(8, "little"))
        h.update(part)
    return h.hexdigest()[:16]


def build_timeout() -> float:
    v = os.environ.get("SWARMCODE_BUILD_TIMEOUT", "").strip()
    if not v:
        return DEFAULT_BUILD_TIMEOUT
    try:
        t = float(v)
    except ValueError:
        raise NativeError(
            f"SWARMCODE_BUILD_TIMEOUT must be a number of seconds, got {v!r}"
        ) from None
    if not 0 <= t <= 86_400:
        raise NativeError(f"SWARMCODE_BUILD_TIMEOUT must be 0-86400 seconds, got {v!r}")
    return t


def _private_dir(path: Path) -> Path:
    """`path`, made 0700 if missing; refused unless it is a real directory of this user that no
    one else can write to."""
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    st = os.lstat(path)
    if stat.S_ISLNK(st.st_mode) or not stat.S_ISDIR(st.st_mode):
        raise NativeError(f"the extension cache {path} is not a directory")
    if st.st_uid != os.getuid():
        raise NativeError(f"the extension cache {path} belongs to another user")
    if st.st_mode & 0o022:
        raise NativeError(f"the extension cache {path} is writable by other users")
    return path


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _acquire(fd: int, timeout: float, where: Path) -> None:
    end = time.monotonic() + timeout
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            if time.monotonic() >= end:
                raise NativeError(
                    f"another process has been building the extension in {where} for more than "
                    f"{timeout:g} s (SWARMCODE_BUILD_TIMEOUT)"
                ) from None
            time.sleep(0.1)


def _import(module_name: str, library: Path):
    loader = importlib.machinery.ExtensionFileLoader(module_name, str(library))
    spec = importlib.util.spec_from_file_location(module_name, str(library), loader=loader)
    if spec is None:
        raise NativeError(f"cannot load {library}")
    mod = importlib.util.module_from_spec(spec)
    loader.exec_module(mod)
    return mod


def build(verbose: bool = False, source: Path = SOURCE):
    """Build (or load the verified cached build of) the extension; raises NativeError or the
    build's exception."""
    text = source.read_bytes()
    key = build_key(text)
    module_name = f"{NAME}_{key}"
    base = cache_base()
    folder = _private_dir(base / f"{NAME}-{key}")
    library = folder / f"{module_name}.so"
    record = folder / HASH_FILE
    fd = os.open(folder / LOCK_FILE, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600)
    try:
        _acquire(fd, build_timeout(), folder)
        if library.is_file() and record.is_file():
            if record.read_text().strip() == _sha256(library):
                return _import(module_name, library)
        # nothing trusted here: start over (no one else builds while the flock is held)
        for stale in (library, record, folder / "lock"):
            if stale.exists() or stale.is_symlink():
                stale.unlink()
        from torch.utils.cpp_extension import load

        mod = load(
            name=module_name,
            sources=[str(source)],
            extra_cflags=list(CFLAGS),
            extra_ldflags=list(LDFLAGS),
            build_directory=str(folder),
            verbose=verbose,
        )
        tmp = record.with_name(record.name + ".tmp")
        tmp.write_text(_sha256(library) + "\n")
        os.replace(tmp, record)
        return mod
    finally:
        os.close(fd)  # releases the flock


def load_extension(verbose: bool = False):
    """The compiled extension module, or None with the reason in `build_error()` (tried once
    per process)."""
    global _module, _error
    with _lock:
        if _module is not None or _error is not None:
            return _module
        try:
            _module = build(verbose)
        except Exception as e:  # noqa: BLE001 - any failure means: the Python tick
            _error = e
        return _module


def build_error() -> Exception | None:
    return _error


def available() -> bool:
    return load_extension() is not None
