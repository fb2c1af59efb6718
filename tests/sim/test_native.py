"""The native extension's cache: keyed by content, private, verified before it is loaded, and a
build lock that neither a killed builder nor a live one can turn into a hang."""

import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from swarmcode_torch.sim import native

built = pytest.mark.skipif(
    not native.available(), reason="the native extension cannot be built here"
)


class WouldBuild(Exception):
    pass


def _no_build(**kw):
    raise WouldBuild(kw["build_directory"])


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A private cache holding a copy of this process's verified build (no 20 s rebuild)."""
    monkeypatch.setenv("SWARMCODE_EXTENSIONS_DIR", str(tmp_path / "base"))
    key = native.build_key(native.SOURCE.read_bytes())
    folder = tmp_path / "base" / f"{native.NAME}-{key}"
    if native.available():
        src = Path(native.load_extension().__file__).parent
        shutil.copytree(src, folder)
        os.chmod(folder, 0o700)
    return folder


def _library(folder):
    return next(folder.glob(f"{native.NAME}_*.so"))


def test_the_key_follows_the_source_and_the_folder_is_private(tmp_path, monkeypatch):
    a, b = native.build_key(b"int a;"), native.build_key(b"int b;")
    assert a != b and a == native.build_key(b"int a;")
    monkeypatch.setenv("SWARMCODE_EXTENSIONS_DIR", str(tmp_path / "x"))
    monkeypatch.setattr("torch.utils.cpp_extension.load", _no_build)
    with pytest.raises(WouldBuild):
        native.build()
    (folder,) = (tmp_path / "x").iterdir()
    assert folder.name.endswith(native.build_key(native.SOURCE.read_bytes()))
    assert folder.stat().st_mode & 0o777 == 0o700


def test_a_folder_others_can_write_to_is_not_used(cache, monkeypatch):
    cache.mkdir(parents=True, exist_ok=True)
    os.chmod(cache, 0o777)
    monkeypatch.setattr("torch.utils.cpp_extension.load", _no_build)
    with pytest.raises(native.NativeError, match="writable by other users"):
        native.build()


@built
def test_a_verified_library_loads_even_beside_a_stale_torch_lock(cache, monkeypatch):
    """torch's own `lock` file, left by a build killed while holding it, made every later run
    wait forever; the verified library loads without a build, and without waiting."""
    (cache / "lock").write_text("")
    monkeypatch.setattr("torch.utils.cpp_extension.load", _no_build)
    t0 = time.monotonic()
    mod = native.build()
    assert hasattr(mod, "run_ticks") and time.monotonic() - t0 < 10


@built
@pytest.mark.parametrize("damage", ["truncate", "replace", "no-record"])
def test_a_damaged_or_unrecorded_library_is_rebuilt_never_loaded(cache, monkeypatch, damage):
    """A truncated library (a killed build, a full disk) would end the process with SIGBUS if
    mapped, and a planted one would run its code: neither is loaded; it is removed with the
    stale lock, and the build starts over."""
    lib = _library(cache)
    if damage == "truncate":
        with open(lib, "r+b") as f:
            f.truncate(lib.stat().st_size // 3)
    elif damage == "replace":
        lib.write_bytes(b"\x7fELF planted")
    else:
        (cache / native.HASH_FILE).unlink()
    (cache / "lock").write_text("")
    monkeypatch.setattr("torch.utils.cpp_extension.load", _no_build)
    with pytest.raises(WouldBuild):
        native.build()
    assert not lib.exists() and not (cache / "lock").exists()


_HOLDER = textwrap.dedent(
    """
    import fcntl, os, sys, time
    fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT, 0o600)
    fcntl.flock(fd, fcntl.LOCK_EX)
    print("held", flush=True)
    time.sleep(60)
    """
)


def _hold(path):
    p = subprocess.Popen(
        [sys.executable, "-c", _HOLDER, str(path)], stdout=subprocess.PIPE, text=True
    )
    assert p.stdout.readline().strip() == "held"
    return p


@pytest.mark.subprocess
def test_a_lock_held_too_long_is_an_error_not_a_wait(cache, monkeypatch):
    cache.mkdir(parents=True, exist_ok=True)
    os.chmod(cache, 0o700)
    holder = _hold(cache / native.LOCK_FILE)
    try:
        monkeypatch.setenv("SWARMCODE_BUILD_TIMEOUT", "0.5")
        t0 = time.monotonic()
        with pytest.raises(native.NativeError, match="more than 0.5 s"):
            native.build()
        assert time.monotonic() - t0 < 5
    finally:
        holder.kill()
        holder.wait()


@pytest.mark.subprocess
def test_a_builder_killed_while_holding_the_lock_leaves_no_lock(cache, monkeypatch):
    cache.mkdir(parents=True, exist_ok=True)
    os.chmod(cache, 0o700)
    holder = _hold(cache / native.LOCK_FILE)
    (cache / "lock").write_text("")  # torch's file lock, which a kill leaves behind
    os.kill(holder.pid, signal.SIGKILL)
    holder.wait()
    monkeypatch.setenv("SWARMCODE_BUILD_TIMEOUT", "5")
    monkeypatch.setattr("torch.utils.cpp_extension.load", _no_build)
    t0 = time.monotonic()
    if native.available():
        assert hasattr(native.build(), "run_ticks")
    else:
        with pytest.raises(WouldBuild):
            native.build()
        assert not (cache / "lock").exists()
    assert time.monotonic() - t0 < 5


@built
@pytest.mark.subprocess
def test_a_run_over_a_truncated_library_falls_back_with_one_warning(cache):
    """The run that used to die with SIGBUS: a fresh process whose cached library is truncated,
    with no compiler (CXX pointing nowhere), runs the Python tick with one warning line."""
    lib = _library(cache)
    with open(lib, "r+b") as f:
        f.truncate(4096)
    code = textwrap.dedent(
        """
        import warnings, torch
        from swarmcode_torch.sim.fused import FusedTicks
        warnings.simplefilter("always")
        with warnings.catch_warnings(record=True) as w:
            ok = FusedTicks().ready()
        print(ok, len(w), str(w[0].message) if w else "")
        """
    )
    env = dict(
        os.environ,
        SWARMCODE_EXTENSIONS_DIR=str(cache.parent),
        CXX="/nonexistent/c++",
        PATH="/nonexistent",
    )
    res = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 0, res.stderr[-2000:]
    ok, count, message = res.stdout.strip().split(" ", 2)
    assert ok == "False" and count == "1" and "running the Python tick" in message
    assert not lib.exists()
