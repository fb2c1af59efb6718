"""Ray, connected: where it is (`check_ray_address`, `ray_session`), whether its workers start
(`wait_started`) and hold the resources asked for (`check_resources`), and its errors in one
line. Ray is imported only when one of these is used (`require_ray`)."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

RAY_INSTALL = 'pip install -e ".[ray]" in the source tree (or pip install "ray>=2.9")'
#: Seconds to wait for Ray's workers (the evaluation actors, the first tasks of a sweep) to
#: start before giving up (SWARMCODE_RAY_START_TIMEOUT overrides it): the cluster may be busy,
#: or its worker processes may fail to start at all (under a virtual-memory limit they fail
#: with "mmap failed" and Ray waits for them forever).
RAY_START_TIMEOUT = 120.0
#: Seconds that interrupted tasks get to write their checkpoints before the driver leaves.
INTERRUPT_GRACE = 60.0


class RayUnavailable(ValueError):
    """Ray is not installed, cannot be reached, or lacks the resources asked for (one line)."""


class ShardError(RuntimeError):
    """An evaluation shard failed (its actor died or raised); one line."""


def one_line(e: BaseException) -> str:
    """'Type: first line of the message' of an exception, on one line."""
    text = next((line.strip() for line in str(e).splitlines() if line.strip()), "")
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def require_ray(what: str):
    """The `ray` module; RayUnavailable naming `what` (the option that needs it) and the extra
    to install when it is missing."""
    try:
        import ray
    except ImportError:
        raise RayUnavailable(f"{what} needs Ray, which is not installed: {RAY_INSTALL}") from None
    return ray


#: The address a local Ray cluster (no --ray-address) listens on.
LOCAL_NODE_IP = "127.0.0.1"
#: Seconds to wait for a Ray cluster at HOST:PORT to answer before giving up
#: (SWARMCODE_RAY_CONNECT_TIMEOUT overrides it).
RAY_CONNECT_TIMEOUT = 15.0
#: The HTTP/2 client preface and an empty SETTINGS frame: a Ray head (its GCS, a gRPC server)
#: answers them with a SETTINGS frame of its own.
_H2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + b"\x00\x00\x00\x04\x00\x00\x00\x00\x00"


def _connect_timeout() -> float:
    try:
        t = float(os.environ.get("SWARMCODE_RAY_CONNECT_TIMEOUT", RAY_CONNECT_TIMEOUT))
    except ValueError:
        t = RAY_CONNECT_TIMEOUT
    return t if 0 < t < 3600 else RAY_CONNECT_TIMEOUT


def _start_timeout() -> float:
    try:
        t = float(os.environ.get("SWARMCODE_RAY_START_TIMEOUT", RAY_START_TIMEOUT))
    except ValueError:
        t = RAY_START_TIMEOUT
    return t if 0 < t <= 86400 else RAY_START_TIMEOUT


def wait_started(ray, refs: list, workers: str, what: str) -> list:
    """The results of `refs`, each an object a Ray worker returns as soon as it has started (an
    actor's `ready()`, a probe task): RayUnavailable, within `_start_timeout()` seconds, when
    some have not started by then (a busy cluster, or worker processes that cannot start: Ray
    would wait for them forever), and when a worker died while starting. `workers` names them
    ('2 evaluation workers'), `what` the option that asked for them."""
    timeout = _start_timeout()
    ready, pending = ray.wait(list(refs), num_returns=len(refs), timeout=timeout)
    if pending:
        raise RayUnavailable(
            f"{what}: Ray could not start {workers} within {timeout:g} s ({len(ready)} of "
            f"{len(refs)} started): the cluster has no free CPUs or GPUs for them, or its "
            'worker processes fail to start ("mmap failed" under a virtual-memory limit, '
            "ulimit -v: raise or lift it); see Ray's logs (/tmp/ray/session_latest/logs on "
            "each node); SWARMCODE_RAY_START_TIMEOUT=SECONDS waits longer"
        )
    try:
        return ray.get(list(refs))
    except Exception as e:  # noqa: BLE001 - a worker that died while starting: one line
        raise RayUnavailable(f"{what}: Ray's {workers} did not start ({one_line(e)})") from None


def check_ray_address(address: str, what: str) -> None:
    """RayUnavailable, within `_connect_timeout()` seconds, unless a HOST:PORT address answers
    as a Ray head does (a gRPC server: it answers the HTTP/2 preface with a SETTINGS frame):
    a closed port, a host that does not answer and a server of another kind are one line here,
    where `ray.init` would wait for them for a long time. 'auto' and ray:// addresses are left
    to Ray."""
    import socket

    if address == "auto" or "://" in address:
        return
    host, sep, port_text = address.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port_text.isdigit() or not 0 < int(port_text) < 65536:
        raise RayUnavailable(
            f"{what}: --ray-address must be auto or HOST:PORT, got {address[:100]!r}"
        )
    timeout = _connect_timeout()
    where = f"the Ray cluster at {address}"
    try:
        with socket.create_connection((host, int(port_text)), timeout=timeout) as sock:
            sock.settimeout(timeout)
            sock.sendall(_H2_PREFACE)
            answer = b""
            deadline = time.monotonic() + timeout
            while len(answer) < 9 and time.monotonic() < deadline:
                chunk = sock.recv(9 - len(answer))
                if not chunk:
                    break
                answer += chunk
    except TimeoutError:
        raise RayUnavailable(
            f"{what}: cannot join {where}: no answer within {timeout:g} s"
        ) from None
    except OSError as e:
        raise RayUnavailable(
            f"{what}: cannot join {where} ({e.strerror or type(e).__name__})"
        ) from None
    if len(answer) < 9 or answer[3] != 0x04:
        raise RayUnavailable(
            f"{what}: cannot join {where}: it does not answer as a Ray head "
            "(no gRPC answer); give the address of the head's GCS, "
            "HOST:6379 by default"
        )


@contextmanager
def ray_session(address: str | None, what: str) -> Iterator[Any]:
    """Ray, connected: the session already open in this process (as it is), else a new one:
    joins the cluster at `address` ('auto', HOST:PORT) or starts a local cluster (None); a
    session opened here is shut down on leaving the block."""
    ray = require_ray(what)
    if ray.is_initialized():
        yield ray
        return
    try:
        if address is None:
            # a local cluster is one node: it listens on the loopback address only
            ray.init(include_dashboard=False, _node_ip_address=LOCAL_NODE_IP)
        else:
            check_ray_address(address, what)
            ray.init(address=address)
    except RayUnavailable:
        raise
    except Exception as e:  # noqa: BLE001 - any failure to connect is one line
        where = f"join the Ray cluster at {address}" if address else "start a local Ray cluster"
        raise RayUnavailable(f"{what}: cannot {where} ({one_line(e)})") from None
    try:
        yield ray
    finally:
        ray.shutdown()


def check_resources(ray, need: dict[str, float], what: str) -> dict[str, float]:
    """RayUnavailable when the cluster has less of a resource ('CPU', 'GPU') than `need` asks
    for at once (Ray would wait for it forever); the cluster's resources."""
    have = ray.cluster_resources()
    for name, amount in need.items():
        if amount > have.get(name, 0.0) + 1e-9:
            raise RayUnavailable(
                f"{what} needs {amount:g} {name} at once, the Ray cluster has "
                f"{have.get(name, 0.0):g}"
            )
    return have
