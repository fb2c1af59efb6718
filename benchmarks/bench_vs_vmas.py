"""Benchmark our world tick against VMAS on the same world: robot-ticks per second side by side.

The world: N disc robots in a square arena with walls, each driving to a random target that is
redrawn when reached (and every 100 ticks), with robot-robot collisions. No obstacles.

* VMAS (optional, ``pip install vmas``): a custom ``BaseScenario`` with N sphere agents
  (``collide=True``, holonomic, not rotatable) and the arena's walls as four ``Line`` landmarks
  (``--vmas-walls lines``, the default) or as the world's ``x_semidim`` / ``y_semidim`` bounds
  (``--vmas-walls semidim``: the agent's centre is clamped, no contact force). Each agent's action
  is a proportional controller toward its goal, computed from the agents' positions (vectorized
  over environments; a Python loop over agents, which is how VMAS's API works). One timed VMAS
  tick is that controller plus ``env.step(actions)``; the goals are redrawn in the scenario's
  ``post_step``.
* Ours: ``swarmcode_torch.sim.step.step``, eager and ``torch.compile(step, dynamic=False,
  fullgraph=True)``, with every robot running the one-leaf behavior tree ``ACT_RANDOM_WALK``
  (drive to a random waypoint, redrawn when reached and every ``waypoint_period`` ticks). The
  scenario is bench_sim's (``scenario_for(N)``: four-niche for N <= 20, swarm200 for N = 200)
  without obstacles; its packages stay in the world, untouched, but our tick still senses them.

Our tick does more work than VMAS's: sensing (distances to every grip point, 14 leaf statuses),
the behavior-tree table lookup, pick-up / drop / delivery bookkeeping, package rigid bodies,
force-limited PD control, energy and stuck accounting, and a contact solver with three
relaxation passes plus an elastic velocity impulse over all [E, N, N] robot pairs. VMAS's step
computes the action checks, holonomic forces, drag, a penalty (soft) contact force per candidate
pair, integration and the per-agent observations (position, velocity, goal offset) and rewards.

Writes benchmarks/results/vmas_<device>.json. Examples:
    OMP_NUM_THREADS=2 python benchmarks/bench_vs_vmas.py --device cpu --envs 16,64 --robots 20,200 --ticks 20
    python benchmarks/bench_vs_vmas.py --device cuda
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_sim import (  # noqa: E402
    PROGRAM_LENGTH,
    estimate_bytes,
    mem_available,
    parse_modes,
    run_mode,
    scenario_for,
)
from common import (
    RESULTS_DIR,
    add_run_options,
    apply_run_options,
    int_list,  # noqa: E402
    load_average,
    run_metadata,
    write_json,
)
from vmas_scenario import (  # noqa: E402
    GOAL_PERIOD,
    REACH,
    VMAS_IMPORT_ERROR,
    overlap_stats,
    run_vmas,
    vmas,
    vmas_description,
)

from swarmcode_torch.sim import bt  # noqa: E402
from swarmcode_torch.sim.hardware import phenotype  # noqa: E402
from swarmcode_torch.sim.layout import make_layouts  # noqa: E402
from swarmcode_torch.sim.scenario import Scenario  # noqa: E402
from swarmcode_torch.sim.state import Robots, WorldParams, compatible, random_keys, reset  # noqa: E402


# ------------------------------------------------------------------ the world
def world_scenario(n: int) -> Scenario:
    """bench_sim's scenario for n robots, without obstacles (VMAS's world has none)."""
    s = scenario_for(n)
    return replace(s, name=f"{s.name}, no obstacles", obstacle_count=0)


class OurWorld:
    """Inputs of our step() for the random-walk world (the interface of bench_sim's Workload,
    so bench_sim.run_mode times it)."""

    def __init__(
        self, scenario: Scenario, E: int, radius: float, seed: int, device: torch.device
    ) -> None:
        g = torch.Generator().manual_seed(seed)
        N = scenario.num_robots
        u = lambda: torch.rand(E, N, generator=g)  # noqa: E731
        tier = lambda: torch.randint(0, 3, (E, N), generator=g)  # noqa: E731
        self.layout = make_layouts(scenario, E, g, device)
        ph = phenotype(
            torch.full((E, N), radius),
            tier(),
            tier(),
            tier(),
            u(),
            u(),
            torch.randint(0, 2, (E, N), generator=g),
        )
        program = bt.encode([bt.ACT_RANDOM_WALK], PROGRAM_LENGTH)[None]  # [1, L]: one leaf
        self.robots = Robots(
            *(
                t.to(device)
                for t in Robots.from_phenotype(
                    ph, torch.ones(E, N, dtype=torch.bool), torch.zeros(E, N, dtype=torch.long)
                )
            )
        )
        self.tables = bt.build_tables(program.to(device))
        self.params = WorldParams.for_scenario(scenario)
        self.compat = compatible(self.layout, self.robots, self.params)
        self.keys = random_keys(self.layout, N)
        self.P, self.G = self.layout.g_effector.shape[1:]
        self.last = None

    def start(self):
        return reset(self.layout, self.robots, self.params)

    def tick(self, fn: Callable, state):
        self.last = fn(
            state, self.layout, self.robots, self.compat, self.keys, self.tables, self.params
        )
        return self.last


OURS_COMPUTES = (
    "swarmcode_torch.sim.step.step: sensing (distances from every robot to every grip point "
    "[E, N, P*G], nearest / randomly preferred takeable grip, 14 leaf statuses); behavior-tree "
    "table lookup (every robot runs the one-leaf tree ACT_RANDOM_WALK); drop / pick-up / "
    "delivery bookkeeping and package states; force-limited cascaded PD control toward the "
    "waypoint; semi-implicit Euler with drag and speed cap; lifted-package rigid bodies; robot-"
    "robot contacts over all [E, N, N] pairs (3 position-relaxation passes and one elastic "
    "velocity impulse); obstacle contacts (none here); walls (clamp + reflect); energy; stuck "
    "counters; waypoint redraw (counter-based hash) when reached or every waypoint_period ticks"
)


# ------------------------------------------------------------------ main
def fmt_rate(x: float | None) -> str:
    return f"{x:14.4g}" if x is not None else f"{'-':>14}"


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
        default=[20, 200],
        help="comma-separated N values (default 20,200)",
    )
    parser.add_argument(
        "--compile",
        choices=("eager", "compile", "both"),
        default="both",
        help="our side: eager step, torch.compile(step, dynamic=False, fullgraph=True), or both",
    )
    parser.add_argument(
        "--modes",
        metavar="LIST",
        help="our ticks to time instead of --compile's, comma-separated: eager, compile, "
        "graphs (CUDA), fused (the C++ tick, CPU), triton (CUDA, or TRITON_INTERPRET=1)",
    )
    parser.add_argument(
        "--ticks",
        type=int,
        default=None,
        help="timed ticks per repeat (default cpu: 20; cuda: 200)",
    )
    parser.add_argument(
        "--vmas-ticks",
        type=int,
        default=None,
        help="timed VMAS ticks per repeat (default cpu: --ticks; cuda: 50, as "
        "a VMAS tick at N = 200 syncs the host once per agent pair)",
    )
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per configuration")
    parser.add_argument("--warmup", type=int, default=3, help="untimed ticks before timing")
    parser.add_argument("--radius", type=float, default=0.2, help="robot radius on both sides (m)")
    parser.add_argument(
        "--vmas-walls",
        choices=("lines", "semidim"),
        default="lines",
        help="VMAS walls: four Line landmarks with collisions (default), or the "
        "world's x_semidim / y_semidim position clamp",
    )
    parser.add_argument(
        "--vmas-substeps", type=int, default=1, help="VMAS physics substeps per tick"
    )
    parser.add_argument(
        "--vmas-u-range",
        type=float,
        default=2.0,
        help="VMAS action (force) limit per axis, N on a 1 kg agent",
    )
    add_run_options(parser)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--mem-fraction",
        type=float,
        default=0.5,
        help="cpu: skip our configurations estimated to need more than this "
        "share of available memory",
    )
    parser.add_argument(
        "--out", default=None, help="output JSON (default benchmarks/results/vmas_<device>.json)"
    )
    return parser


def prepare(parser, args, device: torch.device) -> tuple[list[int], list[int], list[str]]:
    """Fills in the device's defaults in `args`: the E values, N values and our modes to run."""
    cuda = device.type == "cuda"
    envs = args.envs or ([50, 200, 400] if cuda else [16, 64])
    robots = args.robots
    args.ticks = args.ticks or (200 if cuda else 20)
    args.vmas_ticks = args.vmas_ticks or (min(args.ticks, 50) if cuda else args.ticks)
    args.fullgraph, args.compile_mode = True, None  # what bench_sim.run_mode reads
    modes = ["eager", "compile"] if args.compile == "both" else [args.compile]
    if args.modes:
        modes = parse_modes(parser, args.modes)
    return envs, robots, modes


def new_result(args, device: torch.device, envs, robots, modes) -> dict[str, Any]:
    """The output JSON before any measurement: the run, the world and both sides described."""
    result: dict[str, Any] = run_metadata(device)
    result.update(
        {
            "envs": envs,
            "robots": robots,
            "modes": modes,
            "ticks": args.ticks,
            "vmas_ticks": args.vmas_ticks,
            "repeats": args.repeats,
            "warmup": args.warmup,
            "radius": args.radius,
            "cold_compile": args.cold_compile,
            "world": "N disc robots of radius `radius` driving to random targets (redrawn when "
            f"within {REACH} m and every {GOAL_PERIOD} ticks) in a square walled arena, "
            "robot-robot collisions, no obstacles; same arena side and start positions "
            "on both sides",
            "note": "our tick does more work than VMAS's (sensing, behavior-tree lookup, package "
            "bookkeeping, energy, a 3-pass contact solver): see ours.computes and "
            "vmas.step_computes",
            "ours": {
                "computes": OURS_COMPUTES,
                "compile": "torch.compile(step, dynamic=False, fullgraph=True)",
                "program": "ACT_RANDOM_WALK (one leaf)",
            },
            "scenarios": {},
            "results": [],
            "comparison": [],
        }
    )
    if vmas is None:
        print("VMAS is not installed: pip install vmas")
        result["vmas"] = {"installed": False, "error": VMAS_IMPORT_ERROR}
    else:
        result["vmas"] = {"installed": True, **vmas_description(args)}
    return result


def show(rec: dict[str, Any], label: str) -> None:
    """One line of the table printed as the run goes."""
    if "error" in rec or "skipped" in rec:
        print(f"{rec['E']:>5} {rec['N']:>5} {label:>13} {rec.get('error') or rec['skipped']}")
        return
    cs = f"{rec['compile_seconds']:9.1f}" if "compile_seconds" in rec else ""
    print(
        f"{rec['E']:>5} {rec['N']:>5} {label:>13} {rec['ms_per_tick']:9.2f} "
        f"{rec['robot_ticks_per_s']:14.4g} {cs}",
        flush=True,
    )


def measure_vmas(w: OurWorld, scenario: Scenario, E: int, N: int, args, device) -> dict:
    """VMAS, from the same start positions in the same arena."""
    try:
        rec, env = run_vmas(w.layout.start, scenario.arena, args, device)
        del env
    except torch.cuda.OutOfMemoryError:
        rec = {"E": E, "N": N, "sim": "vmas", "mode": "vmas", "error": "out of memory"}
    rec["load_average"] = load_average()
    return rec


def measure_ours(w: OurWorld, E: int, N: int, mode: str, need: int, avail, args, device) -> dict:
    """Our step in `mode` (skipped on the CPU where it is estimated not to fit in memory)."""
    if device.type != "cuda" and avail is not None and need > args.mem_fraction * avail:
        return {
            "E": E,
            "N": N,
            "sim": "ours",
            "mode": mode,
            "skipped": f"estimated {need / 2**30:.1f} GiB",
        }
    try:
        rec = run_mode(w, mode, args, device)
        rec["sim"] = "ours"
        rec["overlap"] = overlap_stats(w.last.pos, w.robots.radius)
    except torch.cuda.OutOfMemoryError:
        rec = {"E": E, "N": N, "sim": "ours", "mode": mode, "error": "out of memory"}
    return rec


def compare_one(result: dict, scenario: Scenario, E: int, N: int, modes, args, device, out) -> None:
    """Both sides on E environments of the scenario for N robots: records, the comparison row,
    the JSON rewritten after each record."""
    row: dict[str, Any] = {"E": E, "N": N}
    w = OurWorld(scenario, E, args.radius, args.seed, device)
    result["scenarios"][str(N)] = {
        "name": scenario.name,
        "arena": scenario.arena,
        "packages": w.P,
        "grips": w.G,
        "obstacles": 0,
    }
    if vmas is not None:
        rec = measure_vmas(w, scenario, E, N, args, device)
        result["results"].append(rec)
        show(rec, "vmas")
        row["vmas"] = rec.get("robot_ticks_per_s")
        write_json(result, out)
    need = estimate_bytes(E, N, w.P * w.G, 0)
    avail = mem_available()
    for mode in modes:
        rec = measure_ours(w, E, N, mode, need, avail, args, device)
        rec["scenario"] = scenario.name
        rec["load_average"] = load_average()
        result["results"].append(rec)
        show(rec, f"ours {mode}")
        row[f"ours_{mode}"] = rec.get("robot_ticks_per_s")
        write_json(result, out)
    for mode in modes:
        if row.get("vmas") and row.get(f"ours_{mode}"):
            row[f"ratio_{mode}"] = row[f"ours_{mode}"] / row["vmas"]
    result["comparison"].append(row)
    del w


def print_comparison(result: dict) -> None:
    """The summary table: robot-ticks/s of VMAS and of each of our modes, and their ratios."""
    modes = result.get("modes", [])
    print("\nrobot-ticks/s; ratio = ours / VMAS")
    head = "".join(f" {'ours ' + m:>14}" for m in modes) + "".join(
        f" {'ratio ' + m:>13}" for m in modes
    )
    print(f"{'E':>5} {'N':>5} {'VMAS':>14}{head}")
    for row in result["comparison"]:
        rates = "".join(f" {fmt_rate(row.get(f'ours_{m}'))}" for m in modes)
        ratios = "".join(
            f" {row[f'ratio_{m}']:13.2f}" if f"ratio_{m}" in row else f" {'-':>13}" for m in modes
        )
        print(f"{row['E']:>5} {row['N']:>5} {fmt_rate(row.get('vmas'))}{rates}{ratios}")


def main() -> None:
    parser = make_parser()
    args = parser.parse_args()
    device = apply_run_options(parser, args)
    envs, robots, modes = prepare(parser, args, device)
    result = new_result(args, device, envs, robots, modes)
    out = Path(args.out) if args.out else RESULTS_DIR / f"vmas_{device.type}.json"
    vtxt = f"VMAS {result['vmas']['version']}" if vmas is not None else "VMAS missing"
    print(
        f"{result['device_name']} | torch {result['torch']} | threads {result['threads']} | {vtxt}"
    )
    print(f"{'E':>5} {'N':>5} {'side':>13} {'ms/tick':>9} {'robot-ticks/s':>14} {'compile s':>9}")
    for N in robots:
        scenario = world_scenario(N)
        for E in envs:
            compare_one(result, scenario, E, N, modes, args, device, out)

    result["load_average_at_end"] = load_average()
    result["date_end"] = time.strftime("%Y-%m-%dT%H:%M:%S")
    write_json(result, out)
    print_comparison(result)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
