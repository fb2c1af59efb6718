"""Ray: the runs of a sweep as Ray tasks, and each generation's evaluation in shards on Ray actors.

Ray is optional (`pip install -e ".[ray]"` in the source tree) and imported only when one of these is
used, never when the package is imported. docs/DISTRIBUTED.md shows local, multi-node and Slurm
clusters.

- `run_tasks` runs a function once per job as Ray tasks, at most `workers` at once, each with
  its CPUs and GPUs (the sweep's per-run function, `sweep_run.sweep_task`), and reports each as it
  ends; a failed job does not stop the others.
- `ShardedEvaluator` is an evaluator for `evolve.Context.evaluator`: it cuts a generation's
  evaluation plan (`evaluation.plan_evaluation`, drawn in the driver) into shards of whole
  evaluations, ships each shard's `SimBatch` (the genome rows its teams use, the teams, their
  environments; `pack_batch`) to one Ray actor, which simulates it with its own tick function on its own
  device (`evaluation.simulate_batch`), and gathers the per-environment metrics. The rollouts
  draw their in-episode randomness from each environment's seed, and every draw of the
  generator stays in the driver, so the scores are those of the unsharded run.
"""

from __future__ import annotations

import os
import pickle
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, fields
from typing import Any

import torch

from ..coevo.evaluation import EvalPlan, SimBatch, gather_metrics, sim_batch, simulate_batch
from ..coevo.population import Population
from ..sim.hardware import Catalog, default_catalog
from ..sim.layout import Layout
from ..sim.runtime import CompiledStep, CudaGraphTicks, tick_function
from ..sim.state import WorldParams

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


# ------------------------------------------------------------------ tasks (sweeps)
def _run_task(fn: Callable, threads: int, hide_gpus: bool, *args):
    """Body of a Ray task: torch's CPU threads set to the task's CPUs, the GPUs hidden from a
    task that reserved none (so that device 'auto' does not take one), then fn(*args)."""
    if hide_gpus:
        os.environ["CUDA_VISIBLE_DEVICES"] = ""
    torch.set_num_threads(max(1, threads))
    return fn(*args)


def _started() -> int:
    """A probe task: returns as soon as a worker runs it."""
    return os.getpid()


def run_tasks(
    fn: Callable,
    jobs: list[tuple],
    *,
    workers: int,
    num_cpus: float,
    num_gpus: float,
    on_finish: Callable[[int, str | None, dict], None] | None = None,
    what: str = "running tasks on Ray",
    on_result: Callable[[int, Any], str | None] | None = None,
) -> list[str | None]:
    """fn(*job) for every job as a Ray task (Ray connected: `ray_session`), at most `workers` at
    once, each reserving `num_cpus` CPUs and `num_gpus` GPUs; fn returns None when the job
    finished, else its error in one line. A task is not retried: its job is reported failed
    (a dead worker: the Ray error, in one line) and the others go on. `on_finish(index, error,
    counts)` is called as each ends (counts: done, running, failed, total). When fn returns
    more than its error, `on_result(index, value)` turns what job `index` returned into its error
    here, in the driver (writing files the task sent back; an exception it raises is the job's
    error). Returns each job's error (None: finished). Ctrl-C (KeyboardInterrupt) cancels the running tasks, which get
    KeyboardInterrupt in turn (a run writes its checkpoint), waits up to INTERRUPT_GRACE seconds
    for them, and re-raises. Before any job, as many probe tasks as will run at once (with the
    same CPUs and GPUs) must start within SWARMCODE_RAY_START_TIMEOUT seconds (`wait_started`),
    else RayUnavailable naming `what` (Ray would wait forever for workers that cannot start)."""
    ray = require_ray(what)
    if jobs:
        probe = ray.remote(num_cpus=num_cpus, num_gpus=num_gpus, max_retries=0)(_started)
        n = min(workers, len(jobs))
        refs = [probe.remote() for _ in range(n)]
        try:
            wait_started(ray, refs, f"{n} worker{'s' if n > 1 else ''} for the runs", what)
        except RayUnavailable:
            for ref in refs:
                try:
                    ray.cancel(ref, force=True)
                except Exception:  # noqa: BLE001 - already gone
                    pass
            raise
    task = ray.remote(num_cpus=num_cpus, num_gpus=num_gpus, max_retries=0)(_run_task)
    threads = max(1, int(num_cpus))
    errors: list[str | None] = [None] * len(jobs)
    pending = list(range(len(jobs)))
    running: dict = {}
    done = failed = 0
    try:
        while pending or running:
            while pending and len(running) < workers:
                i = pending.pop(0)
                running[task.remote(fn, threads, num_gpus == 0, *jobs[i])] = i
            ready, _ = ray.wait(list(running), num_returns=1)
            for ref in ready:
                i = running.pop(ref)
                errors[i] = _task_error(ray, ref, i, on_result)
                if errors[i] is None:
                    done += 1
                else:
                    failed += 1
                if on_finish is not None:
                    on_finish(
                        i,
                        errors[i],
                        {
                            "done": done,
                            "running": len(running),
                            "failed": failed,
                            "total": len(jobs),
                        },
                    )
    except KeyboardInterrupt:
        refs = list(running)
        for ref in refs:
            ray.cancel(ref)
        if refs:
            ended, _ = ray.wait(refs, num_returns=len(refs), timeout=INTERRUPT_GRACE)
            if on_result is not None:  # what the stopped tasks sent back (their checkpoints)
                for ref in ended:
                    _task_error(ray, ref, running[ref], on_result)
        raise
    return errors


def _task_error(ray, ref, i: int, on_result: Callable[[int, Any], str | None] | None):
    """The error of task `ref` (job `i`) that has ended, in one line; None when it finished."""
    try:
        value = ray.get(ref)
        return value if on_result is None else on_result(i, value)
    except ray.exceptions.RayError as e:
        return one_line(e)
    except Exception as e:  # noqa: BLE001 - on_result's failure is this job's error
        return one_line(e)


# ------------------------------------------------------------------ sharded evaluation
_INT_WIDTHS = (torch.int8, torch.int16, torch.int32, torch.int64)
_SAME_SIZE_INT = {2: torch.int16, 4: torch.int32, 8: torch.int64}


def _pack_tensor(t: torch.Tensor) -> tuple:
    """A tensor as (numpy array, dtype name, shape to expand to or None), losslessly smaller:
    a tensor whose rows are all the same (bit for bit: a scenario constant repeated for every
    environment) is sent as one row; integers as the narrowest integer type that holds them."""
    t = t.detach().cpu()
    dtype = t.dtype
    same = False
    if t.dim() > 0 and t.shape[0] > 1:
        bits = (
            t.view(_SAME_SIZE_INT[t.element_size()])
            if t.is_floating_point() and t.element_size() in _SAME_SIZE_INT
            else t
        )
        same = bool((bits == bits[:1]).all())
    base = t[:1] if same else t
    if dtype in _INT_WIDTHS and base.numel():
        lo, hi = int(base.min()), int(base.max())
        small = next(
            w for w in _INT_WIDTHS if torch.iinfo(w).min <= lo and hi <= torch.iinfo(w).max
        )
        if small.itemsize < dtype.itemsize:
            base = base.to(small)
    return (
        base.contiguous().numpy(),
        str(dtype).removeprefix("torch."),
        tuple(t.shape) if same else None,
    )


def _unpack_tensor(packed: tuple) -> torch.Tensor:
    arr, dtype, shape = packed
    t = torch.from_numpy(arr).to(getattr(torch, dtype))
    return t.expand(shape).contiguous() if shape is not None else t


def pack_batch(batch: SimBatch) -> bytes:
    """The bytes a shard is sent: its `SimBatch` (genome rows, teams, environments), pickled
    with `_pack_tensor`'s lossless compaction."""
    p = _pack_tensor
    tree = (
        {f.name: p(getattr(batch.genome, f.name)) for f in fields(Population)},
        p(batch.focal_team),
        p(batch.baseline_team),
        [p(t) for t in batch.layouts],
        batch.trials,
    )
    return pickle.dumps(tree, protocol=pickle.HIGHEST_PROTOCOL)


def unpack_batch(data: bytes, device: torch.device | str = "cpu") -> SimBatch:
    genome, focal, base, layouts, trials = pickle.loads(data)
    u = _unpack_tensor
    return SimBatch(
        Population(**{k: u(v) for k, v in genome.items()}),
        u(focal),
        u(base),
        Layout(*(u(t) for t in layouts)),
        trials,
    ).to(device)


def pack_metrics(m: dict, seconds: float) -> bytes:
    """The bytes a shard sends back: its per-environment metrics and rollout seconds."""
    return pickle.dumps(
        ({k: _pack_tensor(v) for k, v in m.items()}, seconds), protocol=pickle.HIGHEST_PROTOCOL
    )


def unpack_metrics(data: bytes, device: torch.device | str = "cpu") -> tuple[dict, float]:
    m, seconds = pickle.loads(data)
    return {k: _unpack_tensor(v).to(device) for k, v in m.items()}, seconds


@dataclass(frozen=True)
class ShardSpec:
    """What an evaluation actor needs to build its simulator: the world constants, the episode
    length, its device kind and how the tick runs (as the driver's `evolve.make_context` chose),
    and the scenario's hardware catalog its robots are built from."""

    params: WorldParams
    ticks: int
    device: str  # "cpu" or "cuda" (the GPU Ray gave the actor)
    compiled: bool  # torch.compile the tick
    cuda_graphs: bool  # replay it as CUDA graphs
    cuda_graphs_required: bool  # cuda_graphs was set explicitly (a failure is an error)
    threads: int  # torch CPU threads
    hardware: Catalog = field(default_factory=default_catalog)


class EvalShard:
    """The state of one evaluation actor: its tick function (compiled where configured, its own
    kernels and graphs for its shard's shapes) on its own device."""

    def __init__(self, spec: ShardSpec):
        torch.set_num_threads(max(1, spec.threads))
        self.spec = spec
        self.device = torch.device(spec.device)
        # not compiled: the tick the run's own process uses (the fused C++ tick on the CPU)
        fn = CompiledStep() if spec.compiled else tick_function(self.device, compile=False)[0]
        if spec.cuda_graphs:
            fn = CudaGraphTicks(fn, required=spec.cuda_graphs_required)
        self.step_fn = fn

    def ready(self) -> str:
        """Where this actor simulates, e.g. 'cpu (1 threads) on host' or 'cuda:0 (NAME)'."""
        import socket

        if self.device.type == "cuda":
            return (
                f"{self.device} ({torch.cuda.get_device_name(self.device)}) on "
                f"{socket.gethostname()}"
            )
        return f"cpu ({torch.get_num_threads()} threads) on {socket.gethostname()}"

    def simulate(self, payload: bytes) -> bytes:
        """`pack_batch` bytes -> `pack_metrics` bytes of its per-environment metrics."""
        batch = unpack_batch(payload, self.device)
        m, seconds = simulate_batch(
            batch, self.spec.params, self.spec.ticks, self.step_fn, catalog=self.spec.hardware
        )
        return pack_metrics(m, seconds)


def shard_bounds(size: int, shards: int) -> list[tuple[int, int]]:
    """Contiguous ranges of whole evaluations, as even as can be, none empty."""
    n = max(1, min(shards, size))
    cuts = [i * size // n for i in range(n + 1)]
    return list(zip(cuts[:-1], cuts[1:]))


class ShardedEvaluator:
    """An evaluator (`evolve.Context.evaluator`) that simulates each generation's evaluations in
    `workers` shards on Ray actors, one GPU each when the run's device is CUDA, else
    `cpus_per_worker` CPUs (and as many torch threads) each. Ray must be connected
    (`ray_session`). `stats` holds, per generation, the shards, the bytes of the pickled
    arguments sent and results received, and the seconds spent waiting for the shards."""

    def __init__(self, ctx, workers: int, cpus_per_worker: float = 1.0):
        ray = require_ray("--eval-workers")
        self.ray = ray
        self.workers = workers
        self.device = ctx.device
        gpu = ctx.device.type == "cuda"
        what = f"--eval-workers {workers}"
        need = {"CPU": workers * cpus_per_worker}
        if gpu:
            need["GPU"] = float(workers)
        check_resources(
            ray,
            need,
            what
            + (
                " (one GPU each, the run's device is CUDA)"
                if gpu
                else f" x {cpus_per_worker:g} CPU"
            ),
        )
        step = ctx.step_fn
        graphs = isinstance(step, CudaGraphTicks)
        spec = ShardSpec(
            params=ctx.params,
            ticks=ctx.eval_cfg.ticks,
            device="cuda" if gpu else "cpu",
            compiled=ctx.compiled,
            cuda_graphs=graphs,
            cuda_graphs_required=graphs and ctx.cfg.cuda_graphs is not None,
            threads=max(1, int(cpus_per_worker)),
            hardware=ctx.scenario.hardware,
        )
        actor = ray.remote(num_cpus=cpus_per_worker, num_gpus=1 if gpu else 0, max_restarts=0)(
            EvalShard
        )
        self.actors = [actor.remote(spec) for _ in range(workers)]
        try:
            self.where = wait_started(
                ray,
                [a.ready.remote() for a in self.actors],
                f"{workers} evaluation worker{'s' if workers > 1 else ''}",
                what,
            )
        except RayUnavailable:
            self.close()
            raise
        self.stats: list[dict] = []

    def simulate(self, plan: EvalPlan, genome: Population) -> tuple[dict, float]:
        """Per-environment metrics of the whole plan (as `simulate_batch` of it), from the
        shards; the seconds are those of the slowest shard's rollout."""
        ray = self.ray
        bounds = shard_bounds(plan.size, len(self.actors))
        t0 = time.perf_counter()
        refs, sent = [], 0
        for actor, (lo, hi) in zip(self.actors, bounds):
            payload = pack_batch(sim_batch(plan, genome, lo, hi))
            sent += len(payload)
            refs.append(actor.simulate.remote(payload))
        t_sent = time.perf_counter()
        try:
            outs = ray.get(refs)
        except ray.exceptions.RayError as e:
            raise ShardError(f"an evaluation shard failed ({one_line(e)})") from None
        t_back = time.perf_counter()
        results = [unpack_metrics(o, self.device) for o in outs]
        m = gather_metrics([r[0] for r in results])
        seconds = [r[1] for r in results]
        self.stats.append(
            {
                "shards": len(bounds),
                "evaluations": [hi - lo for lo, hi in bounds],
                "bytes_sent": sent,
                "bytes_received": sum(len(o) for o in outs),
                "send_seconds": t_sent - t0,
                "wait_seconds": t_back - t_sent,
                "gather_seconds": time.perf_counter() - t_back,
                "shard_sim_seconds": seconds,
            }
        )
        return m, max(seconds)

    def close(self) -> None:
        for a in getattr(self, "actors", []):
            try:
                self.ray.kill(a)
            except Exception:  # noqa: BLE001 - already gone
                pass
        self.actors = []


@contextmanager
def sharded_evaluation(
    ev, workers: int, address: str | None = None, cpus_per_worker: float = 1.0
) -> Iterator[ShardedEvaluator]:
    """Within the block, `ev` (an `evolve.Evolution`) evaluates each generation in `workers`
    shards on Ray actors (Ray joined at `address`, or a local cluster started, unless this
    process is connected already); the actors are stopped on leaving it.

        with sharded_evaluation(ev, 4, address="auto"):
            session.run(ev, run_dir, reporters)
    """
    with ray_session(address, f"--eval-workers {workers}"):
        evaluator = ShardedEvaluator(ev.ctx, workers, cpus_per_worker)
        ev.ctx.evaluator = evaluator
        try:
            yield evaluator
        finally:
            ev.ctx.evaluator = None
            evaluator.close()
