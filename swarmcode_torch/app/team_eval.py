"""Teams scored on fresh seeds: the one evaluator that `evaluate` (a recorded team of a run, its
knock-outs; `swarmcode-torch evaluate`) and a run's re-evaluation of its best-team candidates
(`best_team`) share.

`draw_layouts`: the environment of each seed, ``make_layouts(scenario, 1,
Generator().manual_seed(seed))`` with the team's robots (the environment `replay --seed SEED`
shows). `run_episodes`: teams [E, S] (rows of one genome) in those environments, all of them one
batch of one rollout (the fused C++ tick on the CPU, the eager tick on CUDA), each team-episode
scored as the run ranked teams (`evaluation.team_scores`, or the run's user function). Each
environment is simulated on its own, so an episode's numbers do not depend on the batch it ran
in. `score_team`: one recorded team (summary.json / teams.jsonl designs) over the seeds, its mean
fitness with its 95 % t interval (`Stat`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import lru_cache

import torch
from torch import Tensor

from ..coevo.config import SwarmCoDeConfig
from ..coevo.evaluation import ScoreFn, _scores, team_robots, team_scores
from ..coevo.fitness import team_cost
from ..coevo.population import Population, from_designs, genome_phenotype
from ..sim import bt
from ..sim.layout import Layout, make_layouts
from ..sim.rollout import rollout
from ..sim.runtime import tick_function, tick_mode
from ..sim.scenario import Scenario
from ..sim.state import DELIVERED, WorldParams

#: The interval every figure is given with.
INTERVAL = "95 % Student t interval of the mean: mean ± t(0.975, n - 1) · sd / √n"

#: The fields of a recorded design that make its robots: two records of a team whose designs
#: agree in these are the same team.
TEAM_GENES = (
    "effector",
    "radius",
    "chassis_tier",
    "battery_tier",
    "motor_tier",
    "torque_point",
    "battery_point",
    "dominance",
    "bt",
    "count",
)

#: progress(stage, done, total): stage "environments" (drawn, one per episode) or "ticks".
ProgressFn = Callable[[str, int, int], None]


# ------------------------------------------------------------------ statistics
def _betacf(a: float, b: float, x: float) -> float:
    """The continued fraction of the regularized incomplete beta function (modified Lentz)."""
    tiny, eps = 1e-300, 3e-16
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 10_000):
        m2 = 2 * m
        aa = m * (b - m) * x / ((qam + m2) * (a + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c if abs(1.0 + aa / c) > tiny else tiny
        h *= d * c
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c if abs(1.0 + aa / c) > tiny else tiny
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < eps:
            break
    return h


def _betainc(a: float, b: float, x: float) -> float:
    """I_x(a, b), the regularized incomplete beta function."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    front = math.exp(
        math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    )
    if x < (a + 1.0) / (a + b + 2.0):
        return front * _betacf(a, b, x) / a
    return 1.0 - front * _betacf(b, a, 1.0 - x) / b


def t_cdf(t: float, df: float) -> float:
    """P(T <= t) of Student's t distribution with `df` degrees of freedom."""
    tail = 0.5 * _betainc(df / 2.0, 0.5, df / (df + t * t))
    return 1.0 - tail if t >= 0 else tail


@lru_cache(maxsize=256)
def t_quantile(p: float, df: float) -> float:
    """The `p` quantile (0.5 <= p < 1) of Student's t with `df` > 0 degrees of freedom, by
    bisection of `t_cdf` (to 1e-12)."""
    if not 0.5 <= p < 1.0 or df <= 0:
        raise ValueError(f"t_quantile needs 0.5 <= p < 1 and df > 0, got p={p}, df={df}")
    lo, hi = 0.0, 1.0
    while t_cdf(hi, df) < p:
        lo, hi = hi, hi * 2.0
    while hi - lo > 1e-12 * max(1.0, hi):
        mid = 0.5 * (lo + hi)
        if t_cdf(mid, df) < p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class Stat:
    """A mean over `n` episodes, its sample standard deviation and 95 % t interval (`INTERVAL`;
    sd and the interval are None for one episode)."""

    mean: float
    sd: float | None
    low: float | None
    high: float | None
    n: int

    @classmethod
    def of(cls, values: Tensor | Sequence[float]) -> Stat:
        v = torch.as_tensor(values, dtype=torch.float64).reshape(-1)
        n = int(v.numel())
        mean = float(v.mean())
        if n < 2:
            return cls(mean, None, None, None, n)
        sd = float(v.std(correction=1))
        half = t_quantile(0.975, n - 1) * sd / math.sqrt(n)
        return cls(mean, sd, mean - half, mean + half, n)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


# ------------------------------------------------------------------ environments and the rollout
def draw_layouts(
    scenario: Scenario, robots: int, seeds: Sequence[int], progress: ProgressFn | None = None
) -> Layout:
    """One environment per seed, as `replay --seed` draws it, stacked [N]."""
    world = replace(scenario, num_robots=robots)
    parts = []
    step = max(1, len(seeds) // 50)
    for i, s in enumerate(seeds):
        parts.append(make_layouts(world, 1, torch.Generator().manual_seed(int(s))))
        if progress is not None and ((i + 1) % step == 0 or i + 1 == len(seeds)):
            progress("environments", i + 1, len(seeds))
    return Layout(*(torch.cat(t) for t in zip(*parts)))


def need_bytes(envs: int, robots: int, layouts: int, world: Scenario) -> int:
    """The memory of `envs` environments of `robots` robots drawn from `layouts` layouts: the
    batch and layout terms of `runconfig.estimate_bytes` (the programs of a few designs are
    nothing beside them)."""
    grips = sum(c.count * len(c.grips) for c in world.packages)
    K, O = world.num_packages, world.obstacle_count
    batch = envs * robots * 16 * (16 + grips + min(robots, 500))
    drawn = layouts * 4 * 32 * (K * (O + 4) + 2 * O) + 3 * 8 * max(robots, world.num_robots) ** 2
    return batch + drawn


class Reporting:
    """A tick function that runs `inner`'s ticks in chunks and reports each (`progress`)."""

    def __init__(self, inner: Callable, progress: ProgressFn, chunks: int = 50):
        self.inner, self.progress, self.chunks = inner, progress, chunks

    def __call__(self, *args):
        return self.inner(*args)

    def run_ticks(self, state, inputs, params, ticks: int):
        step = max(1, -(-ticks // self.chunks))
        done = 0
        self.progress("ticks", 0, ticks)
        while done < ticks:
            n = min(step, ticks - done)
            if hasattr(self.inner, "run_ticks"):
                state = self.inner.run_ticks(state, inputs, params, n)
            else:
                for _ in range(n):
                    state = self.inner(state, *inputs, params)
            done += n
            self.progress("ticks", done, ticks)
        return state


@dataclass(frozen=True, eq=False)
class Episodes:
    """What `run_episodes` returns, on the CPU: each team-episode's score (float64), the team's
    cost, the packages delivered ([E, Q] bool, present packages only), and how the tick ran."""

    scores: Tensor
    cost: Tensor
    delivered: Tensor
    tick: str


def run_episodes(
    genome: Population,
    species: Tensor,
    teams: Tensor,
    layouts: Layout,
    layout_ids: Tensor,
    world: Scenario,
    cfg: SwarmCoDeConfig,
    ticks: int,
    device: torch.device,
    score_fn: ScoreFn = team_scores,
    progress: ProgressFn | None = None,
    step_fn: Callable | None = None,
    tables: Callable[[Tensor], Tensor] = bt.build_tables,
) -> Episodes:
    """Teams [E, S] of `genome`'s rows (-1: an empty slot; `species` [D] of each row) in
    `layouts[layout_ids]`, one rollout of `ticks` ticks on `device` (`step_fn`: the tick,
    default the fused C++ tick on the CPU and the eager tick on CUDA), robots built from the
    world's catalog; each team-episode scored by `score_fn` with the run's evaluation settings
    (`cfg.evaluation`), its cost with the world's species overhead. `tables`: the behavior-tree
    tables of the genome's programs (`bt.build_tables`, or a cache of it)."""
    E = teams.shape[0]
    _, species_index = torch.unique(species, return_inverse=True)
    present = teams >= 0
    seen = torch.zeros(E, int(species_index.max()) + 1, dtype=torch.bool)
    seen[torch.arange(E)[:, None].expand_as(teams)[present], species_index[teams[present]]] = True
    ph = genome_phenotype(genome, world.hardware)
    cost = team_cost(ph.cost[teams.clamp_min(0)], present, seen.sum(1), world.species_overhead)
    if step_fn is None:
        step_fn, compiled = tick_function(device, compile=False)
        mode = tick_mode(step_fn, compiled)
    else:
        mode = tick_mode(step_fn, False)
    if progress is not None:
        step_fn = Reporting(step_fn, progress)
    params = WorldParams.for_scenario(world)
    genome_d = genome.to(device)
    with torch.no_grad():
        m, state = rollout(
            Layout(*(t.to(device) for t in layouts)).select(layout_ids.to(device)),
            team_robots(genome_d, teams.to(device), world.hardware),
            tables(genome_d.bt),
            params,
            ticks,
            step_fn,
            return_state=True,
        )
        ecfg = cfg.evaluation(world.num_robots, world.episode_ticks)
        scores = _scores(score_fn, m, cost.to(device), ecfg).double().cpu()
        done = (state.p_status.cpu() == DELIVERED) & layouts.p_present[layout_ids]
    return Episodes(scores, cost, done, mode)


def team_rows(designs: list[dict], tag_length: int) -> tuple[Population, Tensor]:
    """A recorded team (summary.json / teams.jsonl designs) as (a genome of one row per design,
    [S] the design of each robot slot, in the record's order)."""
    genome, counts = from_designs(designs, tag_length)
    return genome, torch.arange(counts.numel()).repeat_interleave(counts)


def score_team(
    designs: list[dict],
    cfg: SwarmCoDeConfig,
    world: Scenario,
    seeds: Sequence[int],
    ticks: int,
    score_fn: ScoreFn = team_scores,
    layouts: Layout | None = None,
    step_fn: Callable | None = None,
    tables: Callable[[Tensor], Tensor] = bt.build_tables,
) -> Stat:
    """One recorded team's fitness over the environments of `seeds` (`layouts`: theirs, drawn
    here if not given), one batch on the CPU: what `evaluate` gives the team for these seeds
    (`step_fn`, `tables`: as `run_episodes` takes them)."""
    genome, team = team_rows(designs, cfg.tag_length)
    n = len(seeds)
    if layouts is None:
        layouts = draw_layouts(world, int(team.numel()), seeds)
    species = torch.tensor([int(d["species"]) for d in designs])
    ep = run_episodes(
        genome,
        species,
        team.repeat(n, 1),
        layouts,
        torch.arange(n),
        world,
        cfg,
        ticks,
        torch.device("cpu"),
        score_fn,
        step_fn=step_fn,
        tables=tables,
    )
    return Stat.of(ep.scores)
