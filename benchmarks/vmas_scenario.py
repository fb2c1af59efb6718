"""The VMAS side of bench_vs_vmas.py: the same random-walk world as a VMAS ``BaseScenario``
(N sphere agents, the arena's walls as ``Line`` landmarks or as the world's semidim bounds), the
proportional controller that drives each agent toward its goal, the timed VMAS runs, and how
deeply robot pairs overlap (both sides report it). VMAS is optional: this imports without it
(``vmas`` is then None and ``VMAS_IMPORT_ERROR`` says why)."""

from __future__ import annotations

import gc
import math
import sys
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import median, now  # noqa: E402

from swarmcode_torch.sim.state import WorldParams  # noqa: E402

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


# ------------------------------------------------------------------ VMAS
# long: one VMAS scenario class, defined inside this function (its base class comes from VMAS)
# so that this file imports without VMAS installed; its methods are short
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
