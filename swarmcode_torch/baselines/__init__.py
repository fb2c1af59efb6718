"""Baselines for SwarmCoDe on the same scenario, seeds and number of team-episodes.

* `HomogeneousGA`: a plain generational GA over single designs; an individual's team is S clones
  of itself (one species).
* `FixedSpeciesCCEA`: a cooperative co-evolution (Potter & De Jong) with K subpopulations fixed in
  advance, each owning a fixed share of the S team slots; an individual is scored in a team with
  the current representative (best of the previous generation) of every other subpopulation.
* `SwarmCoDeRun`: a thin wrapper over `evolve.Evolution` exposing the same metrics, with the
  dominance-disabled ablation (uniform team composition) as `dominance=False`.

Every algorithm evaluates teams only through `evaluation.simulate_teams`, one batch per generation,
and scores a team-episode with `evaluation.team_scores` (raw fitness x budget penalty, / cost for
ROI) and `fitness.team_cost` (robot costs + species overhead per distinct design in the team).
Team-episodes per generation: SwarmCoDe 2 * P * trials (focal + baseline teams), GA and CCEA
P * trials. `compare` gives every algorithm the same total number of team-episodes and scores the
best team each one found on one common set of held-out environments.

Nothing here prints; the GA and CCEA draw every random number from one explicit torch.Generator
(on the run's device); SwarmCoDe uses `Evolution`'s own generator seeded with `cfg.seed`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace

import torch
from torch import Tensor

from ..coevo.config import SwarmCoDeConfig
from ..coevo.dynamics import mean_std
from ..coevo.evaluation import simulate_teams, team_scores
from ..coevo.evolve import Context, Evolution, GenerationResult, make_context, random_population
from ..coevo.fitness import team_cost
from ..coevo.population import Population, genome_phenotype
from ..coevo.reproduction import ReproductionParams, crossover, mutate
from ..coevo.selection import elite_count, rank_within_groups, top_per_group
from ..sim import bt
from ..sim.layout import Layout, make_layouts
from ..sim.runtime import resolve_device

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
class BestTeam:
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
) -> BestTeam:
    """A BestTeam holding only the rows of `genome` that `team` [S] uses (copies)."""
    rows, inv = torch.unique(team, return_inverse=True)
    return BestTeam(genome.index(rows).clone(), inv.clone(), fitness, cost, generation)


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
    g1 = genome.index(p1)
    cross = crossover(g1, genome.index(p2), generator)
    child = mutate(cross.where(do_cross, g1), params, generator)

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
        self.best: BestTeam | None = None

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

    def _offer(self, candidate: Callable[[], BestTeam], fitness: float) -> None:
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


class HomogeneousGA(_FixedPopulationAlgorithm):
    """A plain GA over single designs: an individual's team is S clones of it (one species).

    Per generation: every individual is scored by `score_teams` on the same T environments
    (one batch of P * T team-episodes), then `reproduce_groups` with one group (elitism,
    tournaments, crossover p = 0.7, mutation). Elites are re-evaluated every generation.
    """

    name = "homogeneous-ga"

    def teams(self) -> Tensor:
        P, S = self.population, self.swarm_size
        return torch.arange(P, device=self.ctx.device)[:, None].expand(P, S).contiguous()

    @property
    def group_sizes(self) -> list[int]:
        return [self.population]


class FixedSpeciesCCEA(_FixedPopulationAlgorithm):
    """Cooperative co-evolution with K species fixed in advance (Potter & De Jong 1994/2000).

    K subpopulations (sizes `split_evenly(P, K)`, stored as consecutive blocks of `genome`); the
    team's S slots are split as `split_evenly(S, K)` (species k always fills `slots[k]` slots).
    Individual i of species k is scored in the team where its species' slots hold i and every
    other species' slots hold that species' representative: a random member in generation 0,
    then the best of the previous generation (the parallel variant: all species are evaluated
    against the previous generation's representatives, in one batch). Reproduction is the GA's,
    inside each subpopulation. The run's best team is the best-scoring evaluated collaboration.
    """

    name = "ccea"

    def __init__(
        self,
        cfg: SwarmCoDeConfig,
        num_species: int,
        generator: torch.Generator,
        resample_environments: bool = True,
    ):
        super().__init__(cfg, generator, resample_environments)
        if not 1 <= num_species <= self.swarm_size:
            raise ValueError(
                f"num_species must be in 1..swarm size {self.swarm_size}, got {num_species}"
            )
        if cfg.population < 2 * num_species:
            raise ValueError(
                f"population {cfg.population} is too small for {num_species} "
                "species (needs >= 2 per species)"
            )
        dev = self.ctx.device
        self.num_species = num_species
        self.sizes = split_evenly(cfg.population, num_species)
        self.slots = split_evenly(self.swarm_size, num_species)
        size_t = torch.tensor(self.sizes, device=dev)
        self.species = torch.repeat_interleave(torch.arange(num_species, device=dev), size_t)
        self.starts = size_t.cumsum(0) - size_t
        self.slot_species = torch.repeat_interleave(
            torch.arange(num_species, device=dev), torch.tensor(self.slots, device=dev)
        )
        u = torch.rand(num_species, generator=generator, device=dev)
        self.representatives = self.starts + (u * size_t).long().clamp(max=size_t - 1)

    def teams(self) -> Tensor:
        """[P, S]: each individual in its species' slots, the representatives in the others."""
        P = self.population
        own = self.slot_species[None, :] == self.species[:, None]
        me = torch.arange(P, device=self.ctx.device)[:, None].expand(P, self.swarm_size)
        return torch.where(own, me, self.representatives[self.slot_species][None, :]).contiguous()

    @property
    def group_sizes(self) -> list[int]:
        return self.sizes

    def _after_reproduction(self) -> None:
        # the best of each subpopulation is its first elite: the first row of its block
        self.representatives = self.starts.clone()


class SwarmCoDeRun(_Algorithm):
    """SwarmCoDe (`evolve.Evolution`) with the baselines' metrics and best-team bookkeeping.

    `dominance=False` is the ablation with uniform team composition. The best team is the best
    focal team of the run (the team of `app.records`' best-team record); its designs are looked up in the
    population it was evaluated in, so that it can be re-scored exactly.
    """

    name = "swarmcode"

    def __init__(self, cfg: SwarmCoDeConfig, dominance: bool | None = None):
        if dominance is not None:
            cfg = replace(cfg, dominance=dominance)
        super().__init__(cfg)
        self.evolution = Evolution(cfg)
        self.name = "swarmcode" if cfg.dominance else "swarmcode-no-dominance"
        self.last_result: GenerationResult | None = None

    @property
    def episodes_per_generation(self) -> int:
        return 2 * self.population * self.trials

    def step(self) -> dict:
        genome = self.evolution.state.genome
        m = self.evolution.step()
        self.last_result = m
        self.episodes += self.episodes_per_generation
        team = m.best_team
        gen = self.generation
        self.generation += 1

        def build() -> BestTeam:
            return _team_of(genome, m.team_rows, team.fitness, team.cost, gen)

        self._offer(build, team.fitness)
        out = self._metrics(team.fitness, int(team.rows.numel()), m.mean_fitness, m.seconds)
        out["species/count"] = m.num_species
        return out


# ------------------------------------------------------------------ generator-style API
def homogeneous_ga(
    cfg: SwarmCoDeConfig, generations: int, generator: torch.Generator, **kw
) -> Iterator[dict]:
    """Run the homogeneous GA for `generations` generations, yielding each one's metrics."""
    algo = HomogeneousGA(cfg, generator, **kw)
    for _ in range(generations):
        yield algo.step()


def fixed_species_ccea(
    cfg: SwarmCoDeConfig, num_species: int, generations: int, generator: torch.Generator, **kw
) -> Iterator[dict]:
    """Run the K-species CCEA for `generations` generations, yielding each one's metrics."""
    algo = FixedSpeciesCCEA(cfg, num_species, generator, **kw)
    for _ in range(generations):
        yield algo.step()


def swarmcode(cfg: SwarmCoDeConfig, generations: int) -> Iterator[dict]:
    """Run SwarmCoDe for `generations` generations, yielding each one's metrics."""
    algo = SwarmCoDeRun(replace(cfg, generations=generations))
    for _ in range(generations):
        yield algo.step()


def swarmcode_no_dominance(cfg: SwarmCoDeConfig, generations: int) -> Iterator[dict]:
    """SwarmCoDe with uniform team composition (dominance genes ignored)."""
    return swarmcode(replace(cfg, dominance=False), generations)


# ------------------------------------------------------------------ comparison
def evaluate_team(best: BestTeam, ctx: Context, layouts: Layout) -> dict:
    """Score a team on the given environments (eagerly, one batch): score, cost, deliveries."""
    team = best.team.to(ctx.device)[None, :]
    genome = best.genome.to(ctx.device)
    score, cost, m = score_teams(ctx, genome, team, layouts)
    return {
        "score": float(score[0]),
        "cost": float(cost[0]),
        "deliveries": float(m["delivered_individual"][0] + m["delivered_collab"][0]),
    }


def plan_generations(episodes_budget: int, population: int, trials: int) -> dict[str, int]:
    """Generations of each algorithm for a budget of team-episodes (a multiple of 2 P T)."""
    unit = 2 * population * trials
    if episodes_budget < unit or episodes_budget % unit:
        raise ValueError(
            f"the episode budget must be a positive multiple of 2 * population * "
            f"trials = {unit}, got {episodes_budget}"
        )
    g = episodes_budget // unit
    return {"swarmcode": g, "swarmcode-no-dominance": g, "homogeneous-ga": 2 * g, "ccea": 2 * g}


def make_algorithm(name: str, cfg: SwarmCoDeConfig, num_species: int = 4) -> _Algorithm:
    """A fresh run of algorithm `name` (see ALGORITHMS) with seed cfg.seed."""
    dev = resolve_device(cfg.device)
    if name == "swarmcode":
        return SwarmCoDeRun(cfg, dominance=True)
    if name == "swarmcode-no-dominance":
        return SwarmCoDeRun(cfg, dominance=False)
    g = torch.Generator(device=dev).manual_seed(cfg.seed)
    if name == "homogeneous-ga":
        return HomogeneousGA(cfg, g)
    if name == "ccea":
        return FixedSpeciesCCEA(cfg, num_species, g)
    raise ValueError(f"unknown algorithm {name!r}; expected one of {', '.join(ALGORITHMS)}")


def compare(
    scenario: str = "four-niche",
    seeds: Sequence[int] = (0, 1, 2),
    generations: int | None = 10,
    episodes_budget: int | None = None,
    population: int = 16,
    swarm_size: int | None = 10,
    trials: int = 1,
    ticks: int | None = 100,
    budget: float | None = None,
    objective: str = "fitness",
    device: str = "auto",
    num_species: int = 4,
    eval_trials: int = 16,
    algorithms: Sequence[str] = ALGORITHMS,
    base: SwarmCoDeConfig | None = None,
    progress: Callable[[dict], None] | None = None,
) -> list[dict]:
    """Run every algorithm on every seed with the same number of team-episodes.

    The budget is `episodes_budget` team-episodes, or `generations` SwarmCoDe generations
    (= generations * 2 * population * trials episodes); the GA and the CCEA get twice as many
    generations. Each run's best team is then scored on `eval_trials` held-out environments
    (seeded by HELD_OUT_SEED, the same for every algorithm and seed; not counted in the budget).
    `base` supplies the remaining SwarmCoDeConfig settings. `progress(row)` is called after each run.

    Returns one row per (algorithm, seed): algorithm, seed, generations, episodes, best_fitness
    (best team score during the run), species (distinct designs in that team), team_cost,
    heldout_fitness, heldout_deliveries, seconds; SwarmCoDe rows add population_species.
    """
    base = base or SwarmCoDeConfig()
    cfg0 = replace(
        base,
        scenario=scenario,
        population=population,
        swarm_size=swarm_size,
        trials=trials,
        ticks=ticks,
        budget=budget,
        objective=objective,
        device=device,
    )
    if episodes_budget is None:
        if generations is None:
            raise ValueError("give generations or episodes_budget")
        episodes_budget = generations * 2 * population * trials
    plan = plan_generations(episodes_budget, population, trials)
    unknown = [a for a in algorithms if a not in ALGORITHMS]
    if unknown:
        raise ValueError(f"unknown algorithms: {', '.join(unknown)}")
    replace(cfg0, generations=1).validate()

    ctx = make_context(replace(cfg0, generations=1, compile=False))
    held_out = new_layouts(
        ctx, eval_trials, torch.Generator(device=ctx.device).manual_seed(HELD_OUT_SEED)
    )
    rows = []
    for seed in seeds:
        for name in algorithms:
            cfg = replace(cfg0, seed=seed, generations=plan[name])
            t0 = time.perf_counter()
            algo = make_algorithm(name, cfg, num_species)
            last = None
            for _ in range(plan[name]):
                last = algo.step()
            seconds = time.perf_counter() - t0
            ev = evaluate_team(algo.best, ctx, held_out)
            row = {
                "algorithm": name,
                "seed": seed,
                "generations": plan[name],
                "episodes": algo.episodes,
                "best_fitness": algo.best.fitness,
                "species": algo.best.species,
                "team_cost": algo.best.cost,
                "heldout_fitness": ev["score"],
                "heldout_deliveries": ev["deliveries"],
                "seconds": seconds,
            }
            if isinstance(algo, SwarmCoDeRun):
                row["population_species"] = last["species/count"]
            rows.append(row)
            if progress is not None:
                progress(row)
    used = {r["episodes"] for r in rows}
    if len(used) > 1:  # pragma: no cover - plan_generations guarantees it
        raise AssertionError(f"unequal episode budgets: {sorted(used)}")
    return rows


SUMMARY_COLUMNS = (
    "best_fitness",
    "heldout_fitness",
    "heldout_deliveries",
    "species",
    "team_cost",
    "seconds",
)


def summarize(rows: list[dict], columns: Sequence[str] = SUMMARY_COLUMNS) -> list[dict]:
    """One row per algorithm (first-seen order): seeds, episodes, and each column's mean and
    sample standard deviation over seeds (`<col>_std`, 0 for a single seed)."""
    groups: dict[str, list[dict]] = {}
    for r in rows:
        groups.setdefault(r["algorithm"], []).append(r)
    out = []
    for name, rs in groups.items():
        s = {
            "algorithm": name,
            "seeds": len(rs),
            "episodes": rs[0]["episodes"],
            "generations": rs[0]["generations"],
        }
        for col in columns:
            s[col], s[f"{col}_std"] = mean_std([float(r[col]) for r in rs])
        out.append(s)
    return out
