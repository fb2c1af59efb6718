"""Seconds per SwarmCoDe generation, and the share spent in simulation, for the paper's setups.

Each configuration is `scenario:swarm_size:population`. The first `--warmup` generations
(which include torch.compile's compile time, reported separately) are not timed.

After the timed generations, one more generation is counted (`--count`, on by default; not
timed): under `torch.profiler`, with the rollout (the tick loop, `evaluation.simulate_teams`)
marked by a `record_function` range, it counts per generation, split into the rollout and the
rest (speciation, partners, team assembly, fitness, reproduction, records):
- `aten_ops`: every aten op call (nested ones included), `aten_top_ops`: those not called by
  another aten op (the dispatches the Python code makes; on the CPU, what launches kernels);
- `local_scalar_dense`: `aten::_local_scalar_dense` calls (`.item()`, `int(t)`, `float(t)`,
  `bool(t)` of a tensor: a device sync on CUDA);
- on CUDA, `kernel_launches` (`cudaLaunchKernel` and kin), `graph_launches` (`cudaGraphLaunch`),
  `dtoh_copies` (device-to-host memcpys), `syncs` (`cudaStreamSynchronize`,
  `cudaDeviceSynchronize`, `cudaEventSynchronize`);
- `host_reads`: device values read on the host, counted on any device by a `TorchFunctionMode`
  (`.item()`, `.tolist()`, `int()`, `float()`, `bool()`, `__index__`, `.numpy()`, `.cpu()`,
  `.to(cpu)` of a tensor that is not a host copy or computed from one: on CUDA, each is a device
  sync; on the CPU, what would be one), with the `host_read_sites` (file:line in the package,
  kind: calls) outside the rollout.
  With a compiled tick the rollout's host reads are not counted (the mode is left off there so
  the compiled tick does not recompile).

    python benchmarks/bench_generation.py --device cpu --configs four-niche:20:50 --generations 2
    python benchmarks/bench_generation.py --device cuda          # the issue's four setups
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import sys
import time
import traceback
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import median, now, parse_configs, run_metadata, write_json  # noqa: E402

from swarmcode_torch.coevo import evaluation  # noqa: E402
from swarmcode_torch.coevo.config import SwarmCoDeConfig  # noqa: E402
from swarmcode_torch.coevo.evolve import Evolution  # noqa: E402

ROLLOUT = "bench::rollout"
HOST_READS = (
    "item",
    "tolist",
    "__bool__",
    "__int__",
    "__float__",
    "__index__",
    "cpu",
    "numpy",
    "to",
)
SHAPE_SYNCS = (
    "nonzero",
    "argwhere",
    "unique",
    "unique_consecutive",
    "masked_select",
    "bincount",
    "repeat_interleave",
)
LAUNCHES = ("cudaLaunchKernel", "cudaLaunchKernelExC", "cuLaunchKernel", "cuLaunchKernelEx")
SYNCS = ("cudaStreamSynchronize", "cudaDeviceSynchronize", "cudaEventSynchronize")
PACKAGE = str(Path(evaluation.__file__).resolve().parents[1])


class HostReads(torch.overrides.TorchFunctionMode):
    """Counts the Tensor methods that read a device value on the host, by call site in the
    package. Host copies (`.cpu()`, `.to(cpu)`: one read each, of a tensor not on the CPU) and
    what is computed from them are host tensors, whose reads are not counted; on a CUDA run, nor
    are reads of any CPU tensor. So a CPU run counts what would be a sync on CUDA."""

    def __init__(self, device: torch.device):
        super().__init__()
        self.device = device
        self.host = torch.utils.weak.WeakIdKeyDictionary()  # host tensors (copies, and derived)
        self.counts = collections.Counter()  # (part, kind) -> calls
        self.sites = collections.Counter()  # (part, "file:line kind") -> calls
        self.part = "rest"

    def _on_host(self, t: torch.Tensor) -> bool:
        return t in self.host or (self.device.type != "cpu" and t.device.type == "cpu")

    def _shape_sync(self, name, args, kwargs) -> bool:
        """An op whose output shape depends on tensor values (a sync on CUDA): nonzero, unique,
        masked_select, bincount, repeat_interleave by a tensor of repeats, indexing or assigning
        by a bool mask."""
        if not args or not isinstance(args[0], torch.Tensor) or self._on_host(args[0]):
            return False
        if name in SHAPE_SYNCS:
            if name == "repeat_interleave":  # by a tensor of repeats, unless sized
                reps = args[1] if len(args) > 1 else kwargs.get("repeats", args[0])
                return "output_size" not in kwargs and isinstance(reps, torch.Tensor)
            return True
        if name in ("__getitem__", "__setitem__") and len(args) > 1:
            idx = args[1] if isinstance(args[1], tuple) else (args[1],)
            return any(isinstance(i, torch.Tensor) and i.dtype == torch.bool for i in idx)
        return False

    def __torch_function__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        name = getattr(func, "__name__", "")
        copy = False
        if name in HOST_READS and args and isinstance(args[0], torch.Tensor):
            copy = name == "cpu" or (name == "to" and _to_cpu(args[1:], kwargs, self.device))
            if (copy or name not in ("to", "cpu")) and not self._on_host(args[0]):
                self.counts[self.part, name] += 1
                self.sites[self.part, f"{_caller()} {name}"] += 1
        elif self._shape_sync(name, args, kwargs):
            self.counts[self.part, "shape"] += 1
            self.sites[self.part, f"{_caller()} shape:{name}"] += 1
        out = func(*args, **kwargs)
        if copy or (
            len(self.host)
            and any(
                isinstance(t, torch.Tensor) and t in self.host
                for t in torch.utils._pytree.tree_leaves((args, kwargs))
            )
        ):
            for t in torch.utils._pytree.tree_leaves(out):
                if isinstance(t, torch.Tensor):
                    self.host[t] = True
        return out


def _to_cpu(args, kwargs, run_device: torch.device) -> bool:
    """Whether `.to(*args, **kwargs)` copies to the host: to the CPU named as a string (how the
    package asks for host copies), or to any CPU device on a run that is not on the CPU (where
    `.to(device)` of a run on the CPU is a move to the run's device, not a copy to the host)."""
    dev = kwargs.get("device", args[0] if args else None)
    if isinstance(dev, torch.Tensor):
        dev = dev.device
    if dev is None or isinstance(dev, torch.dtype):
        return False
    try:
        cpu = torch.device(dev).type == "cpu"
    except (TypeError, RuntimeError):
        return False
    return cpu and (isinstance(dev, str) or run_device.type != "cpu")


def _caller() -> str:
    """file:line of the innermost frame in the package (else the innermost outside torch)."""
    for fr in reversed(traceback.extract_stack()[:-2]):
        if fr.filename.startswith(PACKAGE):
            return f"{Path(fr.filename).relative_to(Path(PACKAGE).parent)}:{fr.lineno}"
    return "elsewhere"


COUNTS = (
    "aten_ops",
    "aten_top_ops",
    "local_scalar_dense",
    "kernel_launches",
    "graph_launches",
    "dtoh_copies",
    "syncs",
)
CUDA_ONLY = ("kernel_launches", "graph_launches", "dtoh_copies", "syncs")


def _profile_step(ev: Evolution, device: torch.device, reads: HostReads, keep_mode: bool):
    """One generation under torch.profiler and `reads`, the rollout marked as ROLLOUT (and, if
    not `keep_mode`, run outside `reads`). Returns the profiler's events."""
    inner = evaluation.simulate_teams

    def marked(*a, **k):
        with contextlib.ExitStack() as stack:
            if not keep_mode:
                stack.enter_context(torch.overrides._pop_mode_temporarily())
            stack.enter_context(torch.profiler.record_function(ROLLOUT))
            reads.part = "rollout"
            try:
                out = inner(*a, **k)
                if device.type == "cuda":
                    torch.cuda.synchronize(device)
                return out
            finally:
                reads.part = "rest"

    acts = [torch.profiler.ProfilerActivity.CPU]
    if device.type == "cuda":
        acts.append(torch.profiler.ProfilerActivity.CUDA)
    evaluation.simulate_teams = marked
    try:
        with torch.profiler.profile(activities=acts) as prof, reads:
            ev.step()
    finally:
        evaluation.simulate_teams = inner
    return prof.events()


def _count_events(events, spans) -> dict:
    """COUNTS of the profiler's CPU events, split into rollout (inside `spans`) and rest."""
    zero = dict.fromkeys(COUNTS, 0)
    out = {"rollout": dict(zero), "rest": dict(zero)}
    for e in events:
        if e.device_type != torch.autograd.DeviceType.CPU or e.name == ROLLOUT:
            continue
        t = e.time_range.start
        c = out["rollout" if any(a <= t <= b for a, b in spans) else "rest"]
        if e.name.startswith("aten::"):
            c["aten_ops"] += 1
            p = e.cpu_parent
            while p is not None and not p.name.startswith("aten::"):
                p = p.cpu_parent
            c["aten_top_ops"] += p is None
            c["local_scalar_dense"] += e.name == "aten::_local_scalar_dense"
            c["dtoh_copies"] += sum(
                "DtoH" in k.name or "Device -> Pageable" in k.name or "Device -> Pinned" in k.name
                for k in e.kernels
            )
        c["kernel_launches"] += e.name in LAUNCHES
        c["graph_launches"] += e.name == "cudaGraphLaunch"
        c["syncs"] += e.name in SYNCS
    return out


def _add_host_reads(out: dict, reads: HostReads, device: torch.device) -> None:
    """Adds the host reads and shape syncs per part to `out` (and drops the CUDA-only counts on
    another device)."""
    for part in out:
        out[part]["host_reads"] = sum(
            n for (p, k), n in reads.counts.items() if p == part and k != "shape"
        )
        out[part]["shape_syncs"] = reads.counts[part, "shape"]
        out[part]["host_reads_by_kind"] = {
            k: n for (p, k), n in sorted(reads.counts.items()) if p == part and k != "shape"
        }
        if device.type != "cuda":
            for k in CUDA_ONLY:
                del out[part][k]


def count_generation(ev: Evolution, device: torch.device) -> dict:
    """Ops, host syncs and kernel launches of one generation, split into rollout and rest."""
    reads = HostReads(device)
    keep_mode = not ev.ctx.compiled  # a compiled tick would recompile under the mode
    events = _profile_step(ev, device, reads, keep_mode)
    spans = [(e.time_range.start, e.time_range.end) for e in events if e.name == ROLLOUT]
    out = _count_events(events, spans)
    _add_host_reads(out, reads, device)
    out["rollout_counted"] = {"host_reads": keep_mode}
    out["rollouts"] = len(spans)
    for part in ("rollout", "rest"):
        out[part]["host_read_sites"] = {
            k: n for (p, k), n in reads.sites.most_common() if p == part
        }
    return out


DEFAULT_CONFIGS = "four-niche:20:50,budget:20:100,swarm200:200:50,swarm1000:1000:50"


def bench(name: str, swarm: int, pop: int, args, device: torch.device) -> dict:
    cfg = SwarmCoDeConfig(
        scenario=name,
        swarm_size=swarm,
        population=pop,
        trials=args.trials,
        ticks=args.ticks,
        generations=args.warmup + args.generations,
        device=str(device),
        compile=args.compile,
        seed=0,
        cuda_graphs=args.cuda_graphs,
    )
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(device)
    ev = Evolution(cfg)
    t0 = now(device)
    for _ in range(args.warmup):
        ev.step()
    warmup_s = now(device) - t0
    gen_s, eval_s, sim_s = [], [], []
    for _ in range(args.generations):
        t = now(device)
        m = ev.step()
        gen_s.append(now(device) - t)
        eval_s.append(m.eval_seconds)
        sim_s.append(m.sim_seconds)
    ticks = ev.ctx.eval_cfg.ticks
    envs = 2 * pop * args.trials
    row = {
        "scenario": name,
        "swarm_size": swarm,
        "population": pop,
        "trials": args.trials,
        "ticks": ticks,
        "envs": envs,
        "compile": ev.ctx.compiled,
        "cuda_graphs": ev.ctx.tick_mode.endswith("CUDA graphs"),
        "warmup_generations": args.warmup,
        "warmup_seconds": warmup_s,
        "seconds_per_generation": median(gen_s),
        "all_generation_seconds": gen_s,
        "sim_share": sum(sim_s) / sum(gen_s),
        "evaluation_share": sum(eval_s) / sum(gen_s),
        "robot_ticks_per_s": envs * swarm * ticks / median(sim_s),
        "minutes_per_500_generations": median(gen_s) * 500 / 60,
    }
    if device.type == "cuda":
        row["peak_memory_bytes"] = torch.cuda.max_memory_allocated(device)
    if args.count:
        row["counts_per_generation"] = count_generation(ev, device)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--configs", default=DEFAULT_CONFIGS, help="scenario:swarm:population,...")
    ap.add_argument("--generations", type=int, default=3, help="timed generations")
    ap.add_argument("--warmup", type=int, default=1, help="untimed generations first")
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--ticks", type=int, default=None, help="episode length [scenario's]")
    ap.add_argument(
        "--compile",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="torch.compile the tick [default: on CUDA only]",
    )
    ap.add_argument(
        "--cuda-graphs",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="replay the compiled tick as CUDA graphs (evolve's cuda_graphs key) "
        "[default: as evolve, on where the tick runs compiled on CUDA]",
    )
    ap.add_argument(
        "--count",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="count ops, host syncs and kernel launches in one more generation "
        "(untimed, under torch.profiler)",
    )
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    device = torch.device(args.device)
    rows = []
    out = args.out or Path(__file__).parent / "results" / f"generation_{device.type}.json"
    for name, swarm, pop in parse_configs(args.configs):
        t = time.perf_counter()
        rows.append(bench(name, swarm, pop, args, device))
        r = rows[-1]
        print(
            f"{name} swarm {swarm} pop {pop}: {r['seconds_per_generation']:.2f} s/gen, "
            f"simulation {100 * r['sim_share']:.0f}%, evaluation {100 * r['evaluation_share']:.0f}%, "
            f"{r['robot_ticks_per_s'] / 1e6:.2f} M robot-ticks/s "
            f"(warm-up {r['warmup_seconds']:.1f} s; {time.perf_counter() - t:.0f} s total)",
            flush=True,
        )
        if "counts_per_generation" in r:
            c = r["counts_per_generation"]
            for part in ("rollout", "rest"):
                print(
                    f"  {part:8s} "
                    + ", ".join(f"{k} {v}" for k, v in c[part].items() if not isinstance(v, dict)),
                    flush=True,
                )
        write_json({**run_metadata(device), "results": rows}, out)  # keep what is done
    write_json({**run_metadata(device), "results": rows}, out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
