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

from bench_sim import PROGRAM_LENGTH, estimate_bytes, mem_available, run_mode, scenario_for  # noqa: E402
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

from swarmcode_torch.sim import bt  # noqa: E402
from swarmcode_torch.sim.hardware import phenotype  # noqa: E402
from swarmcode_torch.sim.layout import make_layouts  # noqa: E402
from swarmcode_torch.sim.scenario import Scenario  # noqa: E402
from swarmcode_torch.sim.state import Robots, WorldParams, compatible, random_keys, reset  # noqa: E402

try:
    import vmas
except ImportError as e:  # VMAS is optional: our side is benchmarked without it
    vmas = None
    VMAS_IMPORT_ERROR: str | None = f"{type(e).__name__}: {e}"
else:
    VMAS_IMPORT_ERROR = None

# The VMAS side mirrors our constants where VMAS has an equivalent.
_DEFAULTS = WorldParams()
GOAL_MARGIN = 0.5  # goals are drawn in [margin, arena - margin]^2, as ours
REACH = _DEFAULTS.reach  # a goal this close is reached and redrawn (m)
GOAL_PERIOD = _DEFAULTS.waypoint_period  # ticks before every goal is redrawn anyway
KP = _DEFAULTS.kp  # proportional gain of the controller (1/s)
MAX_SPEED = _DEFAULTS.v_cap  # m/s
DT = _DEFAULTS.dt  # s per tick


# ------------------------------------------------------------------ the world
def world_scenario(n: int) -> Scenario:
    """bench_sim's scenario for n robots, without obstacles (VMAS's world has none)."""
    s = scenario_for(n)
    return replace(s, name=f"{s.name}, no obstacles", obstacle_count=0)


def overlap_stats(pos: torch.Tensor, radius: torch.Tensor) -> dict[str, float]:
    """pos [E, N, 2], radius [E, N] -> how deeply robot pairs overlap (a check that collisions
    are on: without them, robots driving through each other overlap by up to 2 r)."""
    d = torch.cdist(pos.double(), pos.double())
    rsum = (radius[:, :, None] + radius[:, None, :]).double()
    N = pos.shape[1]
    upper = torch.ones(N, N, dtype=torch.bool, device=pos.device).triu(1)
    pen = torch.where(upper, (rsum - d).clamp_min(0), 0.0)
    touching = pen > 0
    return {
        "pairs_touching": int(touching.sum()),
        "max_overlap_m": float(pen.max()) if pen.numel() else 0.0,
        "mean_overlap_m": float(pen[touching].mean()) if bool(touching.any()) else 0.0,
        "pairs_overlapping_over_half_radius": int((pen > 0.5 * radius.max()).sum()),
    }


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


# ------------------------------------------------------------------ VMAS
def vmas_scenario_class():
    """The VMAS scenario class (built on demand, so this file imports without VMAS)."""
    from vmas.simulator.core import Agent, Landmark, Line, Sphere, World
    from vmas.simulator.scenario import BaseScenario
    from vmas.simulator.utils import ScenarioUtils

    class RandomWalk(BaseScenario):
        """N sphere agents in a walled square arena [-W/2, W/2]^2, each with a goal [E, N, 2]
        that post_step redraws when reached (and every `period` ticks)."""

        def make_world(self, batch_dim: int, device: torch.device, **kwargs):
            self.n = kwargs.pop("n_agents")
            self.arena = kwargs.pop("arena")
            self.radius = kwargs.pop("radius")
            self.start = kwargs.pop("start")  # [E, N, 2] start positions, centred coordinates
            self.walls = kwargs.pop("walls")  # "lines" or "semidim"
            self.reach = kwargs.pop("reach", REACH)
            self.period = kwargs.pop("period", GOAL_PERIOD)
            u_range = kwargs.pop("u_range")
            substeps = kwargs.pop("substeps", 1)
            ScenarioUtils.check_kwargs_consumed(kwargs, warn=False)
            half = self.arena / 2
            semi = half - self.radius if self.walls == "semidim" else None
            world = World(
                batch_dim, device, dt=DT, substeps=substeps, x_semidim=semi, y_semidim=semi
            )
            for i in range(self.n):
                world.add_agent(
                    Agent(
                        name=f"robot_{i}",
                        shape=Sphere(radius=self.radius),
                        collide=True,
                        movable=True,
                        rotatable=False,
                        mass=1.0,
                        u_range=u_range,
                        max_speed=MAX_SPEED,
                    )
                )
            if self.walls == "lines":
                for i in range(4):
                    world.add_landmark(
                        Landmark(
                            name=f"wall_{i}",
                            shape=Line(length=self.arena),
                            collide=True,
                            movable=False,
                            rotatable=False,
                        )
                    )
            self.index = {a.name: i for i, a in enumerate(world.agents)}
            self.goal = torch.zeros(batch_dim, self.n, 2, device=device)
            self.zero = torch.zeros(batch_dim, device=device)
            self.t = 0
            return world

        def draw_goals(self, e: int) -> torch.Tensor:
            half = self.arena / 2 - GOAL_MARGIN
            return (torch.rand(e, self.n, 2, device=self.world.device) * 2 - 1) * half

        def reset_world_at(self, env_index=None):
            half = self.arena / 2
            walls = [
                ((0.0, -half), 0.0),
                ((0.0, half), 0.0),
                ((-half, 0.0), math.pi / 2),
                ((half, 0.0), math.pi / 2),
            ]
            for lm, (xy, rot) in zip(self.world.landmarks, walls):
                lm.set_pos(torch.tensor(xy, device=self.world.device), batch_index=env_index)
                lm.set_rot(torch.tensor([rot], device=self.world.device), batch_index=env_index)
            for i, a in enumerate(self.world.agents):
                start = self.start[:, i] if env_index is None else self.start[env_index, i]
                a.set_pos(start, batch_index=env_index)
            if env_index is None:
                self.goal = self.draw_goals(self.world.batch_dim)
                self.t = 0
            else:
                self.goal[env_index] = self.draw_goals(1)[0]

        def positions(self) -> torch.Tensor:
            return torch.stack([a.state.pos for a in self.world.agents], 1)  # [E, N, 2]

        def post_step(self):
            self.t += 1
            reached = (self.goal - self.positions()).norm(dim=-1) <= self.reach
            if self.t % self.period == 0:
                reached = torch.ones_like(reached)
            self.goal = torch.where(
                reached[..., None], self.draw_goals(self.world.batch_dim), self.goal
            )

        def observation(self, agent):
            i = self.index[agent.name]
            return torch.cat(
                [agent.state.pos, agent.state.vel, self.goal[:, i] - agent.state.pos], -1
            )

        def reward(self, agent):
            return self.zero

    return RandomWalk


def vmas_actions(scenario, kp: float, u_range: float) -> list[torch.Tensor]:
    """The proportional controller: each agent's force toward its goal, [E, 2] per agent."""
    u = (kp * (scenario.goal - scenario.positions())).clamp(-u_range, u_range)
    return list(u.unbind(1))


def run_vmas(
    start: torch.Tensor, arena: float, args, device: torch.device
) -> tuple[dict[str, Any], Any]:
    """Build the VMAS environment, warm up, then time args.repeats runs of args.vmas_ticks ticks."""
    E, N = start.shape[:2]
    rec: dict[str, Any] = {"E": E, "N": N, "sim": "vmas", "mode": "vmas"}
    if device.type == "cuda":
        gc.collect()
        torch.cuda.empty_cache()
        torch.cuda.reset_peak_memory_stats(device)
    scenario = vmas_scenario_class()()
    t0 = now(device)
    env = vmas.make_env(
        scenario=scenario,
        num_envs=E,
        device=device,
        continuous_actions=True,
        seed=args.seed,
        n_agents=N,
        arena=arena,
        radius=args.radius,
        start=start - arena / 2,
        walls=args.vmas_walls,
        u_range=args.vmas_u_range,
        substeps=args.vmas_substeps,
    )
    rec["make_env_seconds"] = now(device) - t0

    def tick(timer: list[float] | None = None):
        if timer is None:
            env.step(vmas_actions(scenario, KP, args.vmas_u_range))
            return
        t0 = now(device)
        actions = vmas_actions(scenario, KP, args.vmas_u_range)
        t1 = now(device)
        env.step(actions)
        t2 = now(device)
        timer[0] += t1 - t0
        timer[1] += t2 - t1

    for _ in range(args.warmup):
        tick()
    times, ctrl, stepped = [], [], []
    for _ in range(args.repeats):
        timer = [0.0, 0.0]
        t0 = now(device)
        for _ in range(args.vmas_ticks):
            tick(timer)
        times.append(now(device) - t0)
        ctrl.append(timer[0])
        stepped.append(timer[1])
    sec = median(times)
    pos = scenario.positions()
    half = arena / 2
    rec.update(
        {
            "ticks": args.vmas_ticks,
            "repeats": args.repeats,
            "seconds": sec,
            "seconds_all": times,
            "controller_seconds": median(ctrl),
            "env_step_seconds": median(stepped),
            "ms_per_tick": 1e3 * sec / args.vmas_ticks,
            "robot_ticks_per_s": E * N * args.vmas_ticks / sec,
            "robot_ticks_per_s_best": E * N * args.vmas_ticks / min(times),
            "env_ticks_per_s": E * args.vmas_ticks / sec,
            "finite": bool(torch.isfinite(pos).all()),
            "agents_collide": all(a.collide for a in env.world.agents),
            "max_wall_penetration_m": float((pos.abs() - (half - args.radius)).clamp_min(0).max()),
            "overlap": overlap_stats(pos, torch.full((E, N), args.radius, device=device)),
        }
    )
    if device.type == "cuda":
        rec["peak_memory_bytes"] = torch.cuda.max_memory_allocated(device)
    return rec, env


def vmas_description(args) -> dict[str, Any]:
    walls = (
        "four Line landmarks (collide=True) on the arena's edges: sphere-line penalty "
        "contact forces"
        if args.vmas_walls == "lines"
        else "World x_semidim = y_semidim = W/2 - r: each agent's centre is clamped into the "
        "arena after integration (no contact force, velocity kept)"
    )
    return {
        "version": getattr(vmas, "__version__", None),
        "walls": args.vmas_walls,
        "walls_how": walls,
        "agents": "Agent(shape=Sphere(radius), collide=True, rotatable=False, mass=1, "
        f"u_range={args.vmas_u_range}, max_speed={MAX_SPEED}), holonomic dynamics",
        "world": f"World(dt={DT}, substeps={args.vmas_substeps}), VMAS defaults otherwise "
        "(drag 0.25, collision_force 100, contact_margin 1e-3)",
        "controller": f"u = clamp({KP} (goal - pos), -u_range, u_range) per axis, from the "
        "agents' stacked positions, outside env.step",
        "goals": f"uniform in the arena less {GOAL_MARGIN} m; redrawn in post_step when within "
        f"{REACH} m, and all every {GOAL_PERIOD} ticks",
        "timed": "per tick: the controller + env.step(actions); controller_seconds and "
        "env_step_seconds split it",
        "step_computes": "per agent: action checks (NaN, range) and force = action; drag; a "
        "Python loop over all entity pairs that keeps those within reach in "
        "some environment (one norm and one host sync per pair); one batched "
        "soft (logaddexp) penalty force over the kept sphere-sphere pairs and "
        "one over sphere-line (wall) pairs; semi-implicit Euler with the speed "
        "cap; post_step goal redraw; per agent observation (pos, vel, goal - "
        "pos), reward (0) and info; done",
    }


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


def main() -> None:
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
    args = parser.parse_args()
    device = apply_run_options(parser, args)
    cuda = device.type == "cuda"
    envs = args.envs or ([50, 200, 400] if cuda else [16, 64])
    robots = args.robots
    args.ticks = args.ticks or (200 if cuda else 20)
    args.vmas_ticks = args.vmas_ticks or (min(args.ticks, 50) if cuda else args.ticks)
    args.fullgraph, args.compile_mode = True, None  # what bench_sim.run_mode reads
    modes = ["eager", "compile"] if args.compile == "both" else [args.compile]

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
    out = Path(args.out) if args.out else RESULTS_DIR / f"vmas_{device.type}.json"
    vtxt = f"VMAS {result['vmas']['version']}" if vmas is not None else "VMAS missing"
    print(
        f"{result['device_name']} | torch {result['torch']} | threads {result['threads']} | {vtxt}"
    )
    print(f"{'E':>5} {'N':>5} {'side':>13} {'ms/tick':>9} {'robot-ticks/s':>14} {'compile s':>9}")

    def show(rec: dict[str, Any], label: str) -> None:
        if "error" in rec or "skipped" in rec:
            print(f"{rec['E']:>5} {rec['N']:>5} {label:>13} {rec.get('error') or rec['skipped']}")
            return
        cs = f"{rec['compile_seconds']:9.1f}" if "compile_seconds" in rec else ""
        print(
            f"{rec['E']:>5} {rec['N']:>5} {label:>13} {rec['ms_per_tick']:9.2f} "
            f"{rec['robot_ticks_per_s']:14.4g} {cs}",
            flush=True,
        )

    for N in robots:
        scenario = world_scenario(N)
        for E in envs:
            row: dict[str, Any] = {"E": E, "N": N}
            w = OurWorld(scenario, E, args.radius, args.seed, device)
            result["scenarios"][str(N)] = {
                "name": scenario.name,
                "arena": scenario.arena,
                "packages": w.P,
                "grips": w.G,
                "obstacles": 0,
            }

            # VMAS, from the same start positions in the same arena
            if vmas is not None:
                try:
                    rec, env = run_vmas(w.layout.start, scenario.arena, args, device)
                    del env
                except torch.cuda.OutOfMemoryError:
                    rec = {"E": E, "N": N, "sim": "vmas", "mode": "vmas", "error": "out of memory"}
                rec["load_average"] = load_average()
                result["results"].append(rec)
                show(rec, "vmas")
                row["vmas"] = rec.get("robot_ticks_per_s")
                write_json(result, out)

            # ours
            need = estimate_bytes(E, N, w.P * w.G, 0)
            avail = mem_available()
            for mode in modes:
                if not cuda and avail is not None and need > args.mem_fraction * avail:
                    rec = {
                        "E": E,
                        "N": N,
                        "sim": "ours",
                        "mode": mode,
                        "skipped": f"estimated {need / 2**30:.1f} GiB",
                    }
                else:
                    try:
                        rec = run_mode(w, mode, args, device)
                        rec["sim"] = "ours"
                        rec["overlap"] = overlap_stats(w.last.pos, w.robots.radius)
                    except torch.cuda.OutOfMemoryError:
                        rec = {
                            "E": E,
                            "N": N,
                            "sim": "ours",
                            "mode": mode,
                            "error": "out of memory",
                        }
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

    result["load_average_at_end"] = load_average()
    result["date_end"] = time.strftime("%Y-%m-%dT%H:%M:%S")
    write_json(result, out)

    print("\nrobot-ticks/s; ratio = ours / VMAS")
    print(
        f"{'E':>5} {'N':>5} {'VMAS':>14} {'ours eager':>14} {'ours compiled':>14} "
        f"{'ratio eager':>11} {'ratio comp.':>11}"
    )
    for row in result["comparison"]:
        ratios = [
            f"{row[k]:11.2f}" if k in row else f"{'-':>11}"
            for k in ("ratio_eager", "ratio_compile")
        ]
        print(
            f"{row['E']:>5} {row['N']:>5} {fmt_rate(row.get('vmas'))} "
            f"{fmt_rate(row.get('ours_eager'))} {fmt_rate(row.get('ours_compile'))} "
            f"{ratios[0]} {ratios[1]}"
        )
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
