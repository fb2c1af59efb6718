"""Benchmark the Triton tick (`sim.triton_tick`, issue #40) against the reference tick on CUDA.

Per configuration E:N (default 400:200, then 50:1000 and 4:10000, where both ticks use their
cell-list broad phase): robot-ticks/s of whole ticks in each mode of --modes, the pair phases
alone (robot contacts with obstacles and walls; robot x grip-point sensing) in ms per call,
and how far one tick of each tick from the same state lies from the reference's.

Modes: `eager` (the Python tick, `step`), `triton` (`step_triton`: step.py with its pair
phases in Triton kernels, the rest eager), `compiled_graphs` (torch.compile'd `step` replayed
from CUDA graphs: the CUDA default), `triton_compiled` (torch.compile of `step_triton`, its
kernels as user-defined Triton kernels; may fail: the error is recorded).

Needs a CUDA device; without one it refuses, unless TRITON_INTERPRET=1, where it runs on the
CPU in Triton's interpreter to check the script (tiny --configs; the times mean nothing).

    python benchmarks/bench_triton_tick.py --out benchmarks/results/triton_tick_cuda.json
    TRITON_INTERPRET=1 python benchmarks/bench_triton_tick.py --configs 2:20,1:600 --ticks 2 \\
        --repeats 1 --out /tmp/triton_tick_interp.json
"""

from __future__ import annotations

import argparse
import gc
import sys
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_sim import Workload, scenario_for  # noqa: E402
from common import RESULTS_DIR, median, now, run_metadata, write_json  # noqa: E402

from swarmcode_torch.sim import triton_tick as tt  # noqa: E402
from swarmcode_torch.sim.contacts import collide  # noqa: E402
from swarmcode_torch.sim.runtime import CudaGraphTicks  # noqa: E402
from swarmcode_torch.sim.sense import sense  # noqa: E402
from swarmcode_torch.sim.state import State, TickInputs  # noqa: E402
from swarmcode_torch.sim.step import step  # noqa: E402


def parse_configs(text: str) -> list[tuple[int, int]]:
    """'400:200,50:1000' -> [(400, 200), (50, 1000)]."""
    out = []
    for item in text.split(","):
        e, n = item.split(":")
        out.append((int(e), int(n)))
    return out


def _state_diff(a: State, b: State) -> dict[str, Any]:
    """Largest float difference per field, and the integer fields that differ."""
    out: dict[str, Any] = {"max_abs": {}, "integer_fields_differ": []}
    for name, x, y in zip(a._fields, a, b):
        if x.dtype.is_floating_point:
            out["max_abs"][name] = float((x - y).abs().max()) if x.numel() else 0.0
        elif not torch.equal(x, y):
            out["integer_fields_differ"].append(name)
    return out


def time_ticks(fn: Callable, w: Workload, state: State, args, device) -> dict[str, Any]:
    """Warm up, then median of args.repeats runs of args.ticks ticks."""
    inputs = TickInputs(w.layout, w.robots, w.compat, w.keys, w.tables)
    rec: dict[str, Any] = {}
    t0 = now(device)
    if isinstance(fn, CudaGraphTicks):
        fn.run_ticks(state, inputs, w.params, fn.k)  # compile and capture
    else:
        s = state
        for _ in range(max(1, args.warmup)):
            s = fn(s, *inputs, w.params)
    rec["first_seconds"] = now(device) - t0  # compile / kernel build included
    times = []
    for _ in range(args.repeats):
        t0 = now(device)
        if isinstance(fn, CudaGraphTicks):
            s = fn.run_ticks(state, inputs, w.params, args.ticks)
        else:
            s = state
            for _ in range(args.ticks):
                s = fn(s, *inputs, w.params)
        times.append(now(device) - t0)
    E, N = w.robots.radius.shape
    sec = median(times)
    rec.update(
        seconds_all=times,
        ms_per_tick=1e3 * sec / args.ticks,
        robot_ticks_per_s=E * N * args.ticks / sec,
        finite=bool(torch.isfinite(s.pos).all()),
    )
    return rec


def time_call(f: Callable, device, reps: int) -> float:
    f()  # warm (kernel build)
    times = []
    for _ in range(reps):
        t0 = now(device)
        f()
        times.append(now(device) - t0)
    return 1e3 * median(times)


def pair_phases(w: Workload, state: State, args, device) -> dict[str, Any]:
    """ms per call of each pair phase, reference against Triton, on `state`'s positions."""
    r = w.robots
    lay = w.layout
    m = r.mass
    col = (state.pos, state.vel, r.radius, m, r.present, lay.o_pos, lay.o_radius, lay.o_present)
    N = r.radius.shape[1]
    reps = max(3, args.repeats)
    out: dict[str, Any] = {
        "contacts_path": "cells" if N >= w.params.broad_phase_min_robots else "dense",
        "contacts_ms_reference": time_call(lambda: collide(*col, w.params), device, reps),
        "contacts_ms_triton": time_call(lambda: tt.collide_triton(*col, w.params), device, reps),
        "sense_ms_reference": time_call(
            lambda: sense(state, lay, r, w.compat, w.keys, w.params), device, reps
        ),
        "sense_ms_triton": time_call(
            lambda: tt.sense_triton(state, lay, r, w.compat, w.keys, w.params), device, reps
        ),
    }
    a = collide(*col, w.params)
    b = tt.collide_triton(*col, w.params)
    out["contacts_max_abs_diff"] = max(float((x - y).abs().max()) for x, y in zip(a, b))
    O = lay.o_pos.shape[1]
    H = w.compat.shape[2]
    out["blocks"] = {
        "dense": tt.dense_blocks(N, O),
        "cells": tt.cells_blocks(N, O),
        "sense": tt.sense_blocks(N, H),
    }
    return out


def run_config(E: int, N: int, args, device) -> dict[str, Any]:
    if device.type == "cuda":
        gc.collect()
        torch.cuda.empty_cache()
        torch.cuda.reset_peak_memory_stats(device)
    scen = scenario_for(N)
    w = Workload(scen, E, args.seed, 16, device)
    rec: dict[str, Any] = {"E": E, "N": N, "scenario": scen.name, "modes": {}}
    # a state some ticks in (robots moving, some contacts), the same for every mode
    state = w.start()
    for _ in range(args.settle):
        state = w.tick(step, state)
    inputs = TickInputs(w.layout, w.robots, w.compat, w.keys, w.tables)
    ref = step(state, *inputs, w.params)
    rec["one_tick_vs_reference"] = _state_diff(ref, tt.step_triton(state, *inputs, w.params))
    rec["pair_phases"] = pair_phases(w, state, args, device)
    for mode in args.modes:
        try:
            if mode == "eager":
                fn: Callable = step
            elif mode == "triton":
                fn = tt.step_triton
            elif mode == "compiled_graphs":
                torch._dynamo.reset()
                fn = CudaGraphTicks(torch.compile(step, dynamic=False), ticks_per_graph=10)
            elif mode == "triton_compiled":
                torch._dynamo.reset()
                fn = torch.compile(tt.step_triton, dynamic=False)
            else:
                raise ValueError(f"unknown mode {mode!r}")
            rec["modes"][mode] = time_ticks(fn, w, state, args, device)
        except Exception as e:  # noqa: BLE001 - record and go on with the next mode
            rec["modes"][mode] = {"error": f"{type(e).__name__}: {str(e).splitlines()[0][:300]}"}
            traceback.print_exc()
        print(f"E={E} N={N} {mode}: {rec['modes'][mode]}", flush=True)
    if device.type == "cuda":
        rec["peak_memory_bytes"] = torch.cuda.max_memory_allocated(device)
    return rec


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--configs", type=parse_configs, default="400:200,50:1000,4:10000")
    parser.add_argument(
        "--modes",
        default="eager,triton",
        help="comma-separated: eager, triton, compiled_graphs, triton_compiled",
    )
    parser.add_argument("--ticks", type=int, default=50, help="timed ticks per repeat")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--warmup", type=int, default=3)
    parser.add_argument("--settle", type=int, default=20, help="reference ticks before timing")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    args.modes = [m.strip() for m in args.modes.split(",") if m.strip()]

    interp = tt.interpreting()
    if torch.cuda.is_available() and not interp:
        device = torch.device("cuda")
    elif interp and tt.available("cpu"):
        device = torch.device("cpu")
        args.modes = [m for m in args.modes if m in ("eager", "triton")]
    else:
        sys.exit(
            "bench_triton_tick.py needs a CUDA device (none here)"
            + ("" if tt.has_triton() else " and triton (pip install -e '.[gpu]')")
            + "; TRITON_INTERPRET=1 runs it on the CPU in Triton's interpreter, to check it"
        )
    if device.type == "cuda" and not tt.available(device):
        sys.exit("bench_triton_tick.py needs triton (pip install -e '.[gpu]')")
    import triton

    out: dict[str, Any] = {
        "meta": run_metadata(device),
        "triton": triton.__version__,
        "interpreter": interp,
        "note": "interpreter: times mean nothing" if interp else "",
        "args": {k: v for k, v in vars(args).items() if k != "configs"},
        "configs": [],
    }
    for E, N in args.configs:
        try:
            out["configs"].append(run_config(E, N, args, device))
        except torch.OutOfMemoryError:
            out["configs"].append({"E": E, "N": N, "error": "out of memory"})
    path = Path(args.out) if args.out else RESULTS_DIR / f"triton_tick_{device.type}.json"
    write_json(out, path)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
