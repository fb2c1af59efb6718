"""Each generation's evaluation in shards on Ray actors (`ShardedEvaluator`): the plan cut into
shards of whole evaluations, each shard's `SimBatch` packed (`pack_batch`) and simulated by one
actor with its own tick function on its own device, the per-environment metrics gathered. Every
draw of the generator stays in the driver, so the scores are those of the unsharded run."""

from __future__ import annotations

import pickle
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, fields

import torch

from ..coevo.evaluation import EvalPlan, SimBatch, gather_metrics, sim_batch, simulate_batch
from ..coevo.population import Population
from ..sim.hardware import Catalog, default_catalog
from ..sim.layout import Layout
from ..sim.runtime import CompiledStep, CudaGraphTicks, tick_function
from ..sim.state import WorldParams
from .ray_cluster import (
    RayUnavailable,
    ShardError,
    check_resources,
    one_line,
    ray_session,
    require_ray,
    wait_started,
)

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
