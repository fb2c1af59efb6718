"""Benchmark the batched world tick: robot-ticks per second over a grid of (E envs, N robots).

Every configuration gets random layouts, robots with random hardware and a mix of template and
random behavior trees, and is run eagerly and/or through ``torch.compile(step, dynamic=False)``.
Scenarios: N <= 20 uses ``four-niche``; N = 200 ``swarm200``; N = 1000 ``swarm1000``; other N use
swarm200 scaled to N robots at the same densities of packages and obstacles.

Writes benchmarks/results/sim_<device>.json. Examples:
    OMP_NUM_THREADS=2 python benchmarks/bench_sim.py --device cpu
    python benchmarks/bench_sim.py --device cuda --envs 50,200,400 --robots 20,200,1000 --compile both
"""

from __future__ import annotations

import argparse
import gc
import math
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import (
    RESULTS_DIR,
    add_run_options,
    apply_run_options,
    int_list,  # noqa: E402
    load_average,
    median,
    now,
    run_metadata,
    write_json,
)

from swarmcode_torch.coevo.population import R_MAX, R_MIN  # noqa: E402
from swarmcode_torch.sim import bt  # noqa: E402
from swarmcode_torch.sim.fused import FusedTicks  # noqa: E402
from swarmcode_torch.sim.hardware import phenotype  # noqa: E402
from swarmcode_torch.sim.layout import make_layouts  # noqa: E402
from swarmcode_torch.sim.runtime import CudaGraphTicks  # noqa: E402
from swarmcode_torch.sim.scenario import Scenario, builtin_names, load_scenario  # noqa: E402
from swarmcode_torch.sim.state import (
    Robots,
    TickInputs,
    WorldParams,
    compatible,  # noqa: E402
    random_keys,
    reset,
)
from swarmcode_torch.sim.step import step  # noqa: E402
from swarmcode_torch.sim.triton_tick import TritonTicks  # noqa: E402
from swarmcode_torch.sim.triton_tick import takes as triton_takes  # noqa: E402

PROGRAM_LENGTH = 32


# ------------------------------------------------------------------ workload
def scaled_swarm(n: int) -> Scenario:
    """swarm200 resized to n robots at the same densities of robots, packages and obstacles.

    Package and obstacle counts scale with n / 200, lengths (arena, base, package distances) with
    sqrt(n / 200). n = 200 gives swarm200 itself.
    """
    s = load_scenario("swarm200")
    if n == s.num_robots:
        return s
    f = n / s.num_robots
    k = math.sqrt(f)
    packages = tuple(
        replace(
            c, count=max(1, round(c.count * f)), distance=(c.distance[0] * k, c.distance[1] * k)
        )
        for c in s.packages
    )
    return replace(
        s,
        name=f"swarm{n} (swarm200 scaled)",
        num_robots=n,
        arena=s.arena * k,
        base_radius=s.base_radius * k,
        obstacle_count=round(s.obstacle_count * f),
        packages=packages,
    )


def scenario_for(n: int) -> Scenario:
    """The benchmark scenario for n robots per environment."""
    if n <= 20:
        s = load_scenario("four-niche")
        return s if n == s.num_robots else replace(s, name=f"four-niche (N={n})", num_robots=n)
    names = builtin_names()
    for name in ("swarm200", "swarm1000"):
        if name in names and load_scenario(name).num_robots == n:
            return load_scenario(name)
    return scaled_swarm(n)


class Workload:
    """Inputs of step() for one configuration, on the benchmark device."""

    def __init__(
        self, scenario: Scenario, E: int, seed: int, n_programs: int, device: torch.device
    ) -> None:
        g = torch.Generator().manual_seed(seed)
        N = scenario.num_robots
        u = lambda: torch.rand(E, N, generator=g)  # noqa: E731
        tier = lambda: torch.randint(0, 3, (E, N), generator=g)  # noqa: E731
        self.layout = make_layouts(scenario, E, g, device)
        ph = phenotype(
            R_MIN + (R_MAX - R_MIN) * u(),
            tier(),
            tier(),
            tier(),
            u(),
            u(),
            torch.randint(0, 2, (E, N), generator=g),
        )
        # programs: the templates first, then random ones
        programs = bt.random_programs(n_programs, PROGRAM_LENGTH, g)
        templates = [bt.template_tensor(k, PROGRAM_LENGTH) for k in bt.TEMPLATES]
        k = min(len(templates), n_programs)
        programs[:k] = torch.stack(templates[:k])
        program = torch.randint(0, n_programs, (E, N), generator=g)
        self.robots = Robots(
            *(
                t.to(device)
                for t in Robots.from_phenotype(ph, torch.ones(E, N, dtype=torch.bool), program)
            )
        )
        self.tables = bt.build_tables(programs.to(device))
        self.params = WorldParams.for_scenario(scenario)
        self.compat = compatible(self.layout, self.robots, self.params)
        self.keys = random_keys(self.layout, N)
        self.P, self.G = self.layout.g_effector.shape[1:]
        self.O = self.layout.o_pos.shape[1]

    def start(self):
        return reset(self.layout, self.robots, self.params)

    def tick(self, fn: Callable, state):
        return fn(state, self.layout, self.robots, self.compat, self.keys, self.tables, self.params)


def estimate_bytes(E: int, N: int, C: int, O: int) -> int:
    """Rough peak working set of one eager tick (the [E, N, N] contact and [E, N, C] sensing
    tensors dominate); used only to skip configurations that cannot fit on the CPU."""
    return 4 * E * (16 * N * N + 12 * N * C + 8 * N * O) + 4096 * E * N


def mem_available() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


# ------------------------------------------------------------------ one configuration
def graphs_compiled() -> int:
    from torch._dynamo.utils import counters

    return int(counters["stats"]["unique_graphs"])


def run_mode(w: Workload, mode: str, args, device: torch.device) -> dict[str, Any]:
    """Warm up, then time args.repeats runs of args.ticks ticks; a result record."""
    E, N = w.robots.radius.shape
    rec: dict[str, Any] = {"E": E, "N": N, "mode": mode}
    if device.type == "cuda":
        gc.collect()
        torch.cuda.empty_cache()
        torch.cuda.reset_peak_memory_stats(device)
    fn: Callable = step
    cudagraphs = False
    state = w.start()
    if mode == "fused":
        return _run_fused(w, rec, state, args, device)
    if mode == "triton":
        fn = TritonTicks()
        if not triton_takes(state, w.robots):
            rec["error"] = (
                "the Triton tick does not run here (CUDA with triton, or TRITON_INTERPRET=1)"
            )
            return rec
    if mode == "graphs":
        # the compiled tick captured in CUDA graphs of --graph-ticks ticks (CudaGraphTicks)
        torch._dynamo.reset()
        g = CudaGraphTicks(
            torch.compile(step, dynamic=False, fullgraph=args.fullgraph),
            ticks_per_graph=args.graph_ticks,
        )
        inputs = TickInputs(w.layout, w.robots, w.compat, w.keys, w.tables)
        t0 = now(device)
        g.run_ticks(state, inputs, w.params, args.graph_ticks)  # compile + capture + replay
        rec["compile_seconds"] = now(device) - t0
        times = []
        for _ in range(args.repeats):
            t0 = now(device)
            out = g.run_ticks(state, inputs, w.params, args.ticks)
            times.append(now(device) - t0)
        rec["graph_ticks"] = args.graph_ticks
        return _timed(rec, times, args, out, device)
    if mode == "compile":
        torch._dynamo.reset()  # a fresh cache: no recompile limit hit, honest compile time
        fn = torch.compile(step, dynamic=False, fullgraph=args.fullgraph, mode=args.compile_mode)
        cudagraphs = device.type == "cuda" and args.compile_mode in (
            "reduce-overhead",
            "max-autotune",
        )
        g0 = graphs_compiled()
        t0 = now(device)
        if cudagraphs:
            torch.compiler.cudagraph_mark_step_begin()
        state = w.tick(fn, state)
        rec["compile_seconds"] = now(device) - t0  # first call: tracing + codegen + one tick
        rec["graphs_compiled"] = graphs_compiled() - g0
    for _ in range(args.warmup):
        if cudagraphs:
            torch.compiler.cudagraph_mark_step_begin()
        state = w.tick(fn, state)
    g1 = graphs_compiled()
    times = []
    for _ in range(args.repeats):
        t0 = now(device)
        for _ in range(args.ticks):
            if cudagraphs:
                torch.compiler.cudagraph_mark_step_begin()
            state = w.tick(fn, state)
        times.append(now(device) - t0)
    if mode == "compile":
        rec["recompiles_while_timed"] = graphs_compiled() - g1
    return _timed(rec, times, args, state, device)


def _run_fused(w: Workload, rec: dict[str, Any], state, args, device) -> dict[str, Any]:
    """The fused C++ tick (`sim.fused.FusedTicks`, the CPU default): all `args.ticks` ticks of a
    run in one call; an error record where it cannot be built or does not take the inputs."""
    fused = FusedTicks()
    if device.type != "cpu" or not fused.ready(warn=False):
        rec["error"] = "the fused C++ tick runs on the CPU only, where it builds"
        return rec
    inputs = TickInputs(w.layout, w.robots, w.compat, w.keys, w.tables)
    for _ in range(max(args.warmup, 1)):
        state = fused.run_ticks(state, inputs, w.params, args.ticks)
    times = []
    for _ in range(args.repeats):
        t0 = now(device)
        out = fused.run_ticks(state, inputs, w.params, args.ticks)
        times.append(now(device) - t0)
    return _timed(rec, times, args, out, device)


def _timed(
    rec: dict[str, Any], times: list[float], args, state, device: torch.device
) -> dict[str, Any]:
    """rec completed with the figures of `times` (seconds per run of args.ticks ticks)."""
    E, N, ticks = rec["E"], rec["N"], args.ticks
    sec = median(times)
    rec.update(
        {
            "ticks": ticks,
            "repeats": args.repeats,
            "seconds": sec,
            "seconds_all": times,
            "ms_per_tick": 1e3 * sec / ticks,
            "robot_ticks_per_s": E * N * ticks / sec,
            "robot_ticks_per_s_best": E * N * ticks / min(times),
            "env_ticks_per_s": E * ticks / sec,
            "finite": bool(torch.isfinite(state.pos).all()),
        }
    )
    if device.type == "cuda":
        rec["peak_memory_bytes"] = torch.cuda.max_memory_allocated(device)
    return rec


def make_parser() -> argparse.ArgumentParser:
    """The command line (`--help`)."""
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    parser.add_argument(
        "--envs",
        type=int_list,
        default=None,
        help="comma-separated E values (default cpu: 16,64; cuda: 50,200,400)",
    )
    parser.add_argument(
        "--robots",
        type=int_list,
        default=None,
        help="comma-separated N values (default cpu: 20,200; cuda: 20,200,1000)",
    )
    parser.add_argument("--compile", choices=("eager", "compile", "both"), default="both")
    parser.add_argument(
        "--modes",
        metavar="LIST",
        help="the ticks to time instead of --compile's, comma-separated: eager, compile, "
        "graphs (CUDA), fused (the C++ tick, CPU), triton (CUDA, or TRITON_INTERPRET=1)",
    )
    parser.add_argument(
        "--cuda-graphs",
        action="store_true",
        help="also time the compiled tick replayed from CUDA graphs (CUDA only)",
    )
    parser.add_argument(
        "--graph-ticks",
        type=int,
        default=10,
        help="ticks captured per CUDA graph (with --cuda-graphs)",
    )
    parser.add_argument(
        "--compile-mode",
        default=None,
        help="torch.compile mode (e.g. reduce-overhead for CUDA graphs)",
    )
    parser.add_argument(
        "--fullgraph",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="compile with fullgraph=True (fail on graph breaks)",
    )
    parser.add_argument(
        "--ticks",
        type=int,
        default=None,
        help="timed ticks per repeat (default cpu: 20; cuda: 200)",
    )
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per configuration")
    parser.add_argument("--warmup", type=int, default=3, help="untimed ticks before timing")
    parser.add_argument(
        "--programs",
        type=int,
        default=16,
        help="distinct behavior trees (the 4 templates, then random ones)",
    )
    add_run_options(parser)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--mem-fraction",
        type=float,
        default=0.5,
        help="cpu: skip configurations estimated to need more than this share of available memory",
    )
    parser.add_argument(
        "--out", default=None, help="output JSON (default benchmarks/results/sim_<device>.json)"
    )
    return parser


#: the ticks a benchmark can time: the eager Python tick, torch.compile'd, compiled in CUDA
#: graphs, the fused C++ tick (CPU), the Python tick with its pair phases in Triton kernels
MODES = ("eager", "compile", "graphs", "fused", "triton")


def parse_modes(parser, text: str) -> list[str]:
    """--modes: a comma-separated list of MODES (a parser error otherwise)."""
    modes = [m.strip() for m in text.split(",") if m.strip()]
    bad = [m for m in modes if m not in MODES]
    if bad or not modes:
        parser.error(f"--modes: expected some of {', '.join(MODES)}, got {text!r}")
    return modes


def prepare(parser, args, device: torch.device) -> tuple[list[int], list[int], list[str]]:
    """Fills in the device's defaults in `args`: the E values, N values and modes to run."""
    cuda = device.type == "cuda"
    envs = args.envs or ([50, 200, 400] if cuda else [16, 64])
    robots = args.robots or ([20, 200, 1000] if cuda else [20, 200])
    args.ticks = args.ticks or (200 if cuda else 20)
    modes = ["eager", "compile"] if args.compile == "both" else [args.compile]
    if args.modes:
        modes = parse_modes(parser, args.modes)
    if args.cuda_graphs:
        if not cuda:
            parser.error("--cuda-graphs needs --device cuda")
        modes.append("graphs")
    return envs, robots, modes


def new_result(args, device: torch.device, envs, robots, modes) -> dict[str, Any]:
    """The output JSON before any measurement."""
    result: dict[str, Any] = run_metadata(device)
    result.update(
        {
            "envs": envs,
            "robots": robots,
            "modes": modes,
            "ticks": args.ticks,
            "repeats": args.repeats,
            "warmup": args.warmup,
            "programs": args.programs,
            "compile_mode": args.compile_mode,
            "fullgraph": args.fullgraph,
            "cold_compile": args.cold_compile,
            "scenarios": {},
            "results": [],
        }
    )
    return result


def show(rec: dict[str, Any], E: int, N: int, mode: str) -> None:
    """One line of the table printed as the run goes."""
    if "error" in rec:
        print(f"{E:>5} {N:>5} {mode:>8} {rec['error']}")
        return
    cs = f"{rec['compile_seconds']:9.1f}" if "compile_seconds" in rec else f"{'':>9}"
    pk = f"{rec['peak_memory_bytes'] / 2**20:9.0f}" if "peak_memory_bytes" in rec else ""
    print(
        f"{E:>5} {N:>5} {mode:>8} {rec['ms_per_tick']:9.2f} "
        f"{rec['robot_ticks_per_s']:14.4g} {cs} {pk}",
        flush=True,
    )


def bench_config(result: dict, scenario: Scenario, E: int, N: int, modes, args, device, out):
    """Every mode on E environments of the scenario for N robots (skipped on the CPU where
    estimated not to fit in memory); the JSON rewritten after each mode."""
    C = scenario.num_packages * scenario.max_grips
    need = estimate_bytes(E, N, C, scenario.obstacle_count)
    avail = mem_available()
    if device.type != "cuda" and avail is not None and need > args.mem_fraction * avail:
        for mode in modes:
            result["results"].append(
                {
                    "E": E,
                    "N": N,
                    "mode": mode,
                    "skipped": f"estimated {need / 2**30:.1f} GiB > "
                    f"{args.mem_fraction} x {avail / 2**30:.1f} GiB available",
                }
            )
        print(f"{E:>5} {N:>5} skipped (estimated {need / 2**30:.1f} GiB)")
        return
    try:
        w = Workload(scenario, E, args.seed, args.programs, device)
    except torch.cuda.OutOfMemoryError:
        for mode in modes:
            result["results"].append({"E": E, "N": N, "mode": mode, "error": "out of memory"})
        print(f"{E:>5} {N:>5} out of memory building inputs")
        return
    result["scenarios"][str(N)] = {
        "name": scenario.name,
        "arena": scenario.arena,
        "packages": w.P,
        "grips": w.G,
        "obstacles": w.O,
        "episode_ticks": scenario.episode_ticks,
    }
    for mode in modes:
        try:
            rec = run_mode(w, mode, args, device)
        except torch.cuda.OutOfMemoryError:
            rec = {"E": E, "N": N, "mode": mode, "error": "out of memory"}
        rec["scenario"] = scenario.name
        rec["load_average"] = load_average()
        result["results"].append(rec)
        show(rec, E, N, mode)
        write_json(result, out)  # keep what is done if a later configuration dies
    del w


def main() -> None:
    parser = make_parser()
    args = parser.parse_args()
    device = apply_run_options(parser, args)
    envs, robots, modes = prepare(parser, args, device)
    result = new_result(args, device, envs, robots, modes)
    out = Path(args.out) if args.out else RESULTS_DIR / f"sim_{device.type}.json"
    print(f"{result['device_name']} | torch {result['torch']} | threads {result['threads']}")
    print(
        f"{'E':>5} {'N':>5} {'mode':>8} {'ms/tick':>9} {'robot-ticks/s':>14} "
        f"{'compile s':>9} {'peak MiB':>9}"
    )
    for N in robots:
        scenario = scenario_for(N)
        for E in envs:
            bench_config(result, scenario, E, N, modes, args, device, out)
    result["load_average_at_end"] = load_average()
    result["date_end"] = time.strftime("%Y-%m-%dT%H:%M:%S")
    write_json(result, out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
