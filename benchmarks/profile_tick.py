"""Profile the compiled tick: kernels per tick, GPU busy time vs wall time, the top kernels.

Answers "what bounds the tick": when the GPU is busy for only a fraction of each tick's wall time,
the tick is bound by launching kernels (host side); when it is busy most of the time, by the
kernels themselves, and the top-kernel table says which.

    python benchmarks/profile_tick.py --device cuda --configs 400:20,400:200,400:1000
    python benchmarks/profile_tick.py --device cuda --configs 400:20,400:200 --cuda-graphs
    OMP_NUM_THREADS=1 python benchmarks/profile_tick.py --device cpu --configs 300:20,64:200 --ticks 10

On the CPU, inductor's kernel profiling (`torch._inductor.config.cpp.enable_kernel_profile`)
names each generated C++ kernel in the profile; the generated code (`run_and_get_code`) says for
each kernel whether inductor vectorised it (`at::vec::Vectorized` in its body) and which ops it
fuses, so each top kernel gets `vectorized` and `ops` (the aten-level names inductor gives it).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch
from torch.profiler import ProfilerActivity, profile

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_sim import Workload, scenario_for  # noqa: E402
from common import RESULTS_DIR, now, run_metadata, write_json  # noqa: E402

from swarmcode_torch.sim.runtime import CudaGraphTicks  # noqa: E402
from swarmcode_torch.sim.state import TickInputs  # noqa: E402
from swarmcode_torch.sim.step import step  # noqa: E402


def _device_us(evt) -> float:
    for name in ("device_time_total", "cuda_time_total", "self_device_time_total"):
        v = getattr(evt, name, None)
        if v:
            return float(v)
    return 0.0


def _cpp_kernels(code: str) -> dict[str, bool]:
    """Generated C++ kernel name -> whether its body uses at::vec (vectorised)."""
    import re

    out = {}
    parts = re.split(r"(cpp_fused_\w+)\s*=\s*async_compile\.cpp_pybinding", code)
    for name, body in zip(parts[1::2], parts[2::2]):
        body = body.split("async_compile.cpp_pybinding")[0]
        out[name] = "at::vec::Vectorized" in body or "at::vec::" in body
    return out


def profile_config(E: int, N: int, args, device: torch.device) -> dict:
    w = Workload(scenario_for(N), E, 0, 16, device)
    torch._dynamo.reset()
    vec = {}
    if device.type == "cpu":
        import torch._inductor.config as ic

        ic.cpp.enable_kernel_profile = True
    fn = torch.compile(step, dynamic=False, fullgraph=True, mode=args.compile_mode)
    if device.type == "cpu":
        from torch._inductor.utils import run_and_get_code

        _, codes = run_and_get_code(lambda s: w.tick(fn, s), w.start())
        for c in codes:
            vec.update(_cpp_kernels(c))
    graphs = args.compile_mode in ("reduce-overhead", "max-autotune")
    state = w.start()

    def tick(s):
        if graphs:
            torch.compiler.cudagraph_mark_step_begin()
        return w.tick(fn, s)

    if args.cuda_graphs:  # the compiled tick replayed from CUDA graphs of 10 ticks, as evolve
        replay = CudaGraphTicks(fn, ticks_per_graph=10)
        inputs = TickInputs(w.layout, w.robots, w.compat, w.keys, w.tables)

        def ticks(s):
            return replay.run_ticks(s, inputs, w.params, args.ticks)
    else:

        def ticks(s):
            for _ in range(args.ticks):
                s = tick(s)
            return s

    for _ in range(2):
        state = ticks(state)  # compile (and capture) outside the timing
    t0 = now(device)
    state = ticks(state)
    wall = (now(device) - t0) / args.ticks
    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device.type == "cuda" else [])
    with profile(activities=activities) as prof:
        state = ticks(state)
        if device.type == "cuda":
            torch.cuda.synchronize()
    if device.type == "cuda":
        kernels = [e for e in prof.events() if e.device_type == torch.autograd.DeviceType.CUDA]
    else:  # inductor's C++ kernels, named by enable_kernel_profile
        kernels = [e for e in prof.events() if "cpp_fused" in e.name]
    busy_us = sum(e.time_range.elapsed_us() for e in kernels) / args.ticks
    table = {}
    for e in kernels:
        k = table.setdefault(e.name, [0, 0.0])
        k[0] += 1
        k[1] += e.time_range.elapsed_us()
    top = sorted(table.items(), key=lambda kv: -kv[1][1])[: args.top]
    return {
        "E": E,
        "N": N,
        "compile_mode": args.compile_mode or "default",
        "cuda_graphs": args.cuda_graphs,
        "wall_ms_per_tick": 1e3 * wall,
        "gpu_busy_ms_per_tick": busy_us / 1e3,
        "gpu_busy_share": busy_us / 1e6 / wall if wall > 0 else None,
        "kernels_per_tick": len(kernels) / args.ticks,
        "robot_ticks_per_s": E * N / wall,
        "top_kernels": [
            {
                "name": n[:120],
                "calls_per_tick": c / args.ticks,
                "us_per_tick": t / args.ticks,
                **(
                    {"vectorized": next((v for k, v in vec.items() if k in n), None)} if vec else {}
                ),
            }
            for n, (c, t) in top
        ],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--configs", default="400:20,400:200,400:1000", help="E:N,...")
    ap.add_argument("--ticks", type=int, default=50)
    ap.add_argument("--top", type=int, default=8)
    ap.add_argument("--compile-mode", default=None)
    ap.add_argument(
        "--cuda-graphs",
        action="store_true",
        help="profile the compiled tick replayed from CUDA graphs (runtime.CudaGraphTicks)",
    )
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    device = torch.device(args.device)
    if args.cuda_graphs and (device.type != "cuda" or args.compile_mode):
        raise SystemExit("--cuda-graphs needs --device cuda and the default compile mode")
    out = args.out or RESULTS_DIR / f"profile_{device.type}.json"
    result = {**run_metadata(device), "results": []}
    for item in args.configs.split(","):
        E, N = (int(x) for x in item.split(":"))
        r = profile_config(E, N, args, device)
        result["results"].append(r)
        print(
            f"E {E} N {N} {r['compile_mode']}: {r['wall_ms_per_tick']:.3f} ms/tick wall, "
            f"GPU busy {r['gpu_busy_ms_per_tick']:.3f} ms ({100 * (r['gpu_busy_share'] or 0):.0f}%), "
            f"{r['kernels_per_tick']:.0f} kernels/tick",
            flush=True,
        )
        for k in r["top_kernels"][:4]:
            print(f"    {k['us_per_tick']:8.1f} us  x{k['calls_per_tick']:.0f}  {k['name'][:80]}")
        write_json(result, out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
