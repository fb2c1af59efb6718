"""What the baselines share: team scoring on common layouts, grouped reproduction, the best
team an algorithm found (`FoundTeam`), and the algorithm base classes."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import torch
from torch import Tensor

from ..coevo.config import SwarmCoDeConfig
from ..coevo.evaluation import simulate_teams, team_scores
from ..coevo.evolve import Context, make_context, random_population
from ..coevo.fitness import team_cost
from ..coevo.population import Population, genome_phenotype
from ..coevo.reproduction import ReproductionParams, mate, mutate
from ..coevo.selection import elite_count, rank_within_groups, top_per_group
from ..sim import bt
from ..sim.layout import Layout, make_layouts

#: Probability that an offspring of the GA / CCEA is a crossover child (else a clone of parent 1).

P_CROSSOVER = 0.7
#: Seed of the held-out environments on which `compare` scores every algorithm's best team.
HELD_OUT_SEED = 20240917

ALGORITHMS = ("swarmcode", "homogeneous-ga", "ccea", "swarmcode-no-dominance")


# ------------------------------------------------------------------ helpers
def split_evenly(n: int, k: int) -> list[int]:
    """n items over k bins as evenly as possible, the larger bins first: (10, 4) -> [3, 3, 2, 2]."""
    if k < 1 or n < 0:
        raise ValueError(f"cannot split {n} into {k} parts")
    q, r = divmod(n, k)
    return [q + 1 if i < r else q for i in range(k)]


def distinct_per_row(teams: Tensor) -> Tensor:
    """[B, S] population rows (-1 empty) -> [B] long number of distinct rows in each team."""
    s = torch.sort(teams, dim=1).values
    new = torch.ones_like(s, dtype=torch.bool)
    new[:, 1:] = s[:, 1:] != s[:, :-1]
    return (new & (s >= 0)).sum(1)


@dataclass(frozen=True, eq=False)
class FoundTeam:
    """A team found by an algorithm: designs [D] (a Population) and its S slots (rows into it)."""

    genome: Population
    team: Tensor  # [S] long rows of `genome`
    fitness: float  # its score in the run (mean over the run's trials)
    cost: float
    generation: int

    @property
    def species(self) -> int:
        """Distinct designs in the team (each a species, by construction in every algorithm)."""
        return int(torch.unique(self.team).numel())


def _team_of(
    genome: Population, team: Tensor, fitness: float, cost: float, generation: int
) -> FoundTeam:
    """A FoundTeam holding only the rows of `genome` that `team` [S] uses (copies)."""
    rows, inv = torch.unique(team, return_inverse=True)
    return FoundTeam(genome.index(rows).clone(), inv.clone(), fitness, cost, generation)


def score_teams(
    ctx: Context,
    genome: Population,
    teams: Tensor,
    layouts: Layout,
    tables: Tensor | None = None,
    step_fn=None,
) -> tuple[Tensor, Tensor, dict]:
    """Teams [B, S] (rows of genome), each run in every one of the T environments `layouts`,
    all B * T team-episodes in one `simulate_teams` batch.

    Returns (score [B] mean over the T environments, team cost [B], episode metrics [B] means).
    The team cost counts the species overhead once per distinct design in the team.
    """
    B = teams.shape[0]
    T = int(layouts.seed.shape[0])
    dev = teams.device
    flat = teams.repeat_interleave(T, 0)  # [B*T, S]
    layout_ids = torch.arange(T, device=dev).repeat(B)
    if tables is None:
        tables = bt.build_tables(genome.bt)
    m = simulate_teams(
        flat,
        genome,
        tables,
        layout_ids,
        layouts,
        ctx.params,
        ctx.eval_cfg.ticks,
        step_fn,
        ctx.scenario.hardware,
    )
    robot_cost = genome_phenotype(genome, ctx.scenario.hardware).cost[flat.clamp_min(0)]
    cost = team_cost(robot_cost, flat >= 0, distinct_per_row(flat), ctx.scenario.species_overhead)
    score = team_scores(m, cost, ctx.eval_cfg).view(B, T).mean(1)
    means = {k: v.float().view(B, T).mean(1) for k, v in m.items()}
    return score, cost.view(B, T)[:, 0], means


def new_layouts(ctx: Context, num: int, generator: torch.Generator) -> Layout:
    """`num` random environments of the run's scenario with the run's team size."""
    scenario = replace(ctx.scenario, num_robots=ctx.eval_cfg.swarm_size)
    return make_layouts(scenario, num, generator, ctx.device)


# ------------------------------------------------------------------ reproduction
def reproduce_groups(
    genome: Population,
    fitness: Tensor,
    sizes: Sequence[int],
    max_elite: int,
    generator: torch.Generator,
    params: ReproductionParams | None = None,
    p_crossover: float = P_CROSSOVER,
) -> tuple[Population, Tensor, Tensor]:
    """Generational reproduction inside fixed groups (the GA: one group; the CCEA: K).

    genome [P] and fitness [P] hold the groups as consecutive blocks of `sizes` rows; the children
    [P] keep that layout. In each group of size n, the best `elite_count(n, max_elite)` (the
    SwarmCoDe elite rule) are copied unchanged, best first; the rest of the group are offspring:
    parent 1 by a tournament (size `params.tournament_size`, with replacement; `params` default:
    `ReproductionParams`, the run defaults; the algorithms pass their run's) in the group,
    parent 2 by a tournament among the other members (parent 1 again only if the group has one
    member), uniform `crossover` with probability `p_crossover` (else a clone of parent 1), then
    `mutate`. Ties rank the lower row first.

    Returns (children [P], is_elite [P] bool, parent [P] row of the elite / of parent 1).
    """
    params = params or ReproductionParams(max_elite=max_elite)
    dev = genome.bt.device
    P = genome.size
    size_t = torch.tensor(list(sizes), dtype=torch.long, device=dev)
    if int(size_t.sum()) != P or bool((size_t < 1).any()):
        raise ValueError(f"group sizes {list(sizes)} do not partition {P} individuals")
    k = size_t.numel()
    pos = torch.repeat_interleave(torch.arange(k, device=dev), size_t)  # [P] group of each row
    starts = size_t.cumsum(0) - size_t
    fit = torch.nan_to_num(fitness.float(), nan=-math.inf)

    order, rank = rank_within_groups(pos, fit, size_t)  # by (group, fitness desc, row)
    n_elite = torch.minimum(elite_count(size_t, max_elite), size_t)
    elite = top_per_group(order, rank, pos, n_elite)  # by group, best first

    off_pos = torch.repeat_interleave(torch.arange(k, device=dev), size_t - n_elite)
    n_off = off_pos.numel()
    ts = params.tournament_size
    n = size_t[off_pos][:, None]  # [N, 1]
    base = starts[off_pos][:, None]
    local1 = (torch.rand(n_off, ts, generator=generator, device=dev) * n).long().clamp(max=n - 1)
    w1 = fit[order[base + local1]].argmax(1, keepdim=True)
    l1 = local1.gather(1, w1)  # [N, 1] rank of p1
    m = (n - 1).clamp(min=1)
    local2 = (torch.rand(n_off, ts, generator=generator, device=dev) * m).long().clamp(max=m - 1)
    local2 = torch.where(n > 1, local2 + (local2 >= l1).long(), local2)  # skip p1's rank
    w2 = fit[order[base + local2]].argmax(1, keepdim=True)
    p1 = order[base + l1].squeeze(1)
    p2 = order[base + local2.gather(1, w2)].squeeze(1)

    do_cross = torch.rand(n_off, generator=generator, device=dev) < p_crossover
    child = mutate(mate(genome, p1, p2, do_cross, generator), params, generator)

    # each group's block: its elites then its offspring
    group = torch.cat([pos[elite], off_pos])
    perm = torch.sort(group, stable=True).indices
    children = Population.cat([genome.index(elite), child]).index(perm)
    is_elite = torch.cat(
        [
            torch.ones(elite.numel(), dtype=torch.bool, device=dev),
            torch.zeros(n_off, dtype=torch.bool, device=dev),
        ]
    )[perm]
    parent = torch.cat([elite, p1])[perm]
    return children, is_elite, parent


# ------------------------------------------------------------------ algorithms
class _Algorithm:
    """Shared bookkeeping: generation counter, team-episodes, best team of the run."""

    name = "algorithm"

    def __init__(self, cfg: SwarmCoDeConfig):
        self.cfg = cfg
        self.ctx = make_context(cfg)
        self.generation = 0
        self.episodes = 0
        self.best: FoundTeam | None = None

    @property
    def population(self) -> int:
        return self.cfg.population

    @property
    def swarm_size(self) -> int:
        return self.ctx.eval_cfg.swarm_size

    @property
    def trials(self) -> int:
        return self.ctx.eval_cfg.trials

    @property
    def episodes_per_generation(self) -> int:
        raise NotImplementedError

    def step(self) -> dict:
        raise NotImplementedError

    def _offer(self, candidate: Callable[[], FoundTeam], fitness: float) -> None:
        """Keep the run's best team: replaced only by a strictly better score."""
        if self.best is None or fitness > self.best.fitness:
            self.best = candidate()

    def _metrics(self, gen_best: float, gen_species: int, mean: float, seconds: float) -> dict:
        return {
            "generation": self.generation - 1,
            "best": self.best.fitness,
            "best/species": self.best.species,
            "team/fitness": gen_best,
            "team/species": gen_species,
            "fitness/mean": mean,
            "episodes": self.episodes,
            "seconds": seconds,
        }


class _FixedPopulationAlgorithm(_Algorithm):
    """A generational algorithm with P individuals scored by one team each on T environments."""

    def __init__(
        self, cfg: SwarmCoDeConfig, generator: torch.Generator, resample_environments: bool = True
    ):
        super().__init__(cfg)
        if torch.device(generator.device).type != self.ctx.device.type:
            raise ValueError(
                f"the generator is on {generator.device}, the run on {self.ctx.device}"
            )
        self.generator = generator
        self.resample_environments = resample_environments
        self.genome = random_population(cfg.population, cfg, generator, self.ctx.device)
        self._fixed = (
            None if resample_environments else new_layouts(self.ctx, self.trials, generator)
        )
        self.last_scores: Tensor | None = None

    @property
    def episodes_per_generation(self) -> int:
        return self.population * self.trials

    def environments(self) -> Layout:
        """This generation's T environments, shared by every individual (fresh each generation
        unless `resample_environments` is False)."""
        return (
            self._fixed
            if self._fixed is not None
            else new_layouts(self.ctx, self.trials, self.generator)
        )

    @property
    def group_sizes(self) -> list[int]:
        """Sizes of the reproduction groups (consecutive blocks of the population)."""
        raise NotImplementedError

    def teams(self) -> Tensor:
        """[P, S] the team (population rows) that scores each individual."""
        raise NotImplementedError

    def _after_reproduction(self) -> None:
        """Hook run once the next generation exists."""

    def step(self) -> dict:
        t0 = time.perf_counter()
        teams = self.teams()
        score, cost, _ = score_teams(
            self.ctx, self.genome, teams, self.environments(), step_fn=self.ctx.step_fn
        )
        self.episodes += self.episodes_per_generation
        b = int(score.argmax())
        gen_best = float(score[b])
        genome, gen = self.genome, self.generation
        self._offer(lambda: _team_of(genome, teams[b], gen_best, float(cost[b]), gen), gen_best)
        self.last_scores = score
        self.genome, _, _ = reproduce_groups(
            self.genome,
            score,
            self.group_sizes,
            self.cfg.max_elite,
            self.generator,
            self.cfg.reproduction,
        )
        self._after_reproduction()
        self.generation += 1
        species = int(distinct_per_row(teams[b : b + 1])[0])
        return self._metrics(gen_best, species, float(score.mean()), time.perf_counter() - t0)
