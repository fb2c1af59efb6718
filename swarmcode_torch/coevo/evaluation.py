"""Evaluation of a whole population in one simulator batch (paper: "Evaluation and Fitness").

Every individual gets a focal team (itself, one elite of each partner species, dominance-sampled
clones) and a baseline team (its slots refilled from the partners), each run over the same
`trials` random environments. All focal and baseline trials of a generation are one batch of
E = 2 * B * trials environments through one tick loop.

`evaluate` is three steps, so that the simulation can run elsewhere: `plan_evaluation` (the
driver: partners, team assembly and environments, every random draw of the evaluation, from the
run's generator), `simulate_batch` (a pure function of a `SimBatch` of whole evaluations: genome
rows, teams, environments; the rollouts draw their in-episode randomness from each environment's
seed, so any split of the batch gives the same metrics) and `score_plan` (fitness from the
per-environment metrics, in the driver).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import torch
from torch import Tensor

from ..sim import bt
from ..sim.hardware import Catalog, Phenotype
from ..sim.layout import Layout, make_layouts
from ..sim.rollout import rollout
from ..sim.scenario import Scenario
from ..sim.state import Robots, WorldParams, capabilities
from ..sim.tensors import arange, cast
from .config import EvalConfig
from .fitness import budget_penalty, gate, raw_fitness, team_cost
from .partners import (
    Swarms,
    assemble_swarms,
    choose_partners,
    elite_rows,
    niche_representatives,
    ranking_fitness,
)
from .population import Population, genome_phenotype
from .selection import elite_count

StepFn = Callable


@dataclass(frozen=True, eq=False)
class EvalResult:
    """Scores of B evaluated individuals, and everything about their focal teams."""

    fitness: Tensor  # [B] gated fitness of each individual (before EMA smoothing)
    focal: Tensor  # [B] focal team score (mean over trials)
    baseline: Tensor  # [B] baseline team score
    team_cost: Tensor  # [B] focal team cost ($)
    swarms: Swarms  # team compositions (population rows per slot)
    team_metrics: dict  # name -> [B] focal team episode metrics, mean over trials
    sim_seconds: float = 0.0  # wall time of the rollout alone (device synchronised)


def team_scores(metrics: dict, cost: Tensor, cfg: EvalConfig) -> Tensor:
    """[E] score of each team-episode: F_raw times the budget penalty (divided by cost for ROI).
    The built-in `ScoreFn`: a run may be given another (`Context.score_fn`)."""
    f = raw_fitness(metrics, cfg.weights) * budget_penalty(cost, cfg.budget, cfg.lam)
    if cfg.objective == "roi":
        f = f / cost.clamp_min(1.0)
    return f


ScoreFn = Callable[[dict, Tensor, EvalConfig], Tensor]
"""A team-episode score: (metrics: name -> [E] tensor (`rollout.episode_metrics`: deliveries,
pick-ups, energy, proximity, closeness, ...), cost: [E] team cost in $, cfg: the run's
EvalConfig) -> [E] score. The gate, the mean over trials and the EMA apply to it as to
`team_scores`'s."""


def score_fn_name(fn: ScoreFn) -> str:
    """How a config records a user score function: "module.qualname"; for a function without a
    name of its own (a lambda, or one defined inside another function: `<lambda>`, `<locals>` in
    its qualified name) "module.qualname#CODE", CODE a hash of its code, so that two different
    lambdas are not taken for one (the hash depends on the Python version's bytecode)."""
    module = getattr(fn, "__module__", None) or "?"
    qualname = getattr(fn, "__qualname__", None) or type(fn).__qualname__
    name = f"{module}.{qualname}"
    inner = fn
    while getattr(inner, "__wrapped__", None) is not None:  # functools.wraps wrappers
        inner = getattr(inner, "__wrapped__")  # noqa: B009
    code = getattr(inner, "__code__", None)
    if "<" in qualname and code is not None:
        import hashlib
        import marshal

        try:
            name += "#" + hashlib.sha256(marshal.dumps(code)).hexdigest()[:12]
        except ValueError:  # a code object marshal cannot write
            pass
    return name


def _scores(score_fn: ScoreFn, m: dict, cost: Tensor, cfg: EvalConfig) -> Tensor:
    """score_fn's [E] scores, checked when it is not the built-in one."""
    if score_fn is team_scores:
        return team_scores(m, cost, cfg)
    out = score_fn(m, cost, cfg)
    who = f"the fitness function {score_fn_name(score_fn)}"
    if not isinstance(out, Tensor):
        raise TypeError(
            f"{who} must return a tensor of shape {tuple(cost.shape)}, got {type(out).__name__}"
        )
    if out.shape != cost.shape:
        raise ValueError(
            f"{who} must return one score per team-episode, shape "
            f"{tuple(cost.shape)}, got {tuple(out.shape)}"
        )
    out = out.to(device=cost.device, dtype=torch.float32)
    if not bool(torch.isfinite(out).all()):
        raise ValueError(f"{who} returned a NaN or infinite score")
    return out


def team_robots(
    genome: Population,
    teams: Tensor,
    catalog: Catalog | None = None,
    phenotype: Phenotype | None = None,
) -> Robots:
    """Per-robot constants of teams [E, S] of population rows (-1: an empty slot), built from
    `catalog` (the scenario's `hardware`; default: the built-in one); each robot runs its row's
    program (row of `bt.build_tables(genome.bt)`). `phenotype`: the genome's, if computed."""
    ph = phenotype if phenotype is not None else genome_phenotype(genome, catalog)
    rows = teams.clamp_min(0)
    return Robots(
        radius=ph.radius[rows],
        mass=ph.mass[rows],
        force=ph.force[rows],
        payload=ph.payload[rows],
        capacity=ph.capacity[rows],
        efficiency=ph.efficiency[rows],
        effector=ph.effector[rows],
        present=teams >= 0,
        program=rows,
    )


def simulate_teams(
    teams: Tensor,
    genome: Population,
    tables: Tensor,
    layout_ids: Tensor,
    layouts: Layout,
    params: WorldParams,
    ticks: int,
    step_fn: StepFn | None = None,
    catalog: Catalog | None = None,
    phenotype: Phenotype | None = None,
) -> dict:
    """Run teams [E, S] (population rows, -1 empty) in layouts[layout_ids], robots built from
    `catalog` (`team_robots`; `phenotype`: the genome's, if computed); metrics [E] each."""
    return rollout(
        layouts.select(layout_ids),
        team_robots(genome, teams, catalog, phenotype),
        tables,
        params,
        ticks,
        step_fn,
    )


@dataclass(frozen=True, eq=False)
class EvalPlan:
    """What the driver draws for a batch of B evaluations: the teams (population rows) and the
    environments. Trial t of evaluation i runs in `layouts` row i * trials + t, for the focal and
    the baseline team alike."""

    swarms: Swarms  # [B] focal and baseline teams
    layouts: Layout  # [B * trials] environments
    trials: int

    @property
    def size(self) -> int:
        return int(self.swarms.focal_team.shape[0])


@dataclass(frozen=True, eq=False)
class SimBatch:
    """Whole evaluations to simulate, self-contained (what an evaluation shard receives): the
    genome rows their teams use, the teams as rows of that genome, their environments."""

    genome: Population  # the rows the teams use
    focal_team: Tensor  # [B, S] rows of `genome` (-1: an empty slot)
    baseline_team: Tensor  # [B, S]
    layouts: Layout  # [B * trials], as in EvalPlan
    trials: int

    def to(self, device: torch.device | str) -> SimBatch:
        return SimBatch(
            self.genome.to(device),
            self.focal_team.to(device),
            self.baseline_team.to(device),
            Layout(*(t.to(device) for t in self.layouts)),
            self.trials,
        )


def plan_evaluation(
    genome: Population,
    species: Tensor,
    proto_ids: Tensor,
    proto_index: Tensor,
    fitness: Tensor,
    has_fitness: Tensor,
    scenario: Scenario,
    cfg: EvalConfig,
    generator: torch.Generator,
    allowed: Tensor | None = None,
    proto_distance: Tensor | None = None,
    phenotype: Phenotype | None = None,
    always: Tensor | None = None,
) -> EvalPlan:
    """The driver's part of an evaluation, every random draw of it from the run's generator:
    partners by tag and selectivity, team slots by dominance, and the environments. Only the
    diagnostic `partners_per_niche = "one"` reads the scenario's package classes (`niche_partners`);
    the default reads genomes, species and fitness alone. `allowed` [K] bool: the species that
    may be partners at all (`admission.Admission.allowed`); None: every species.
    `proto_distance` [K, K]: the design distance between the species' prototypes
    (`speciation.design_distance`); given, a focal's baseline re-fills its slots from its
    nearest partner species (`partner_admission = "substitute"`), else from any partner.
    `always` [K] bool: species that are partners of every focal whatever the tags
    (`team_partners`)."""
    P = genome.size
    dev = genome.bt.device
    S, T = cfg.swarm_size, cfg.trials
    elites = elite_rows(  # elite_count is at most max(1, max_elite)
        fitness,
        has_fitness,
        species,
        proto_ids,
        lambda n: elite_count(n, cfg.max_elite),
        width=max(cfg.max_elite, 1),
    )
    if cfg.partners_per_niche == "one":
        oracle = niche_partners(
            genome, species, proto_ids, elites, fitness, has_fitness, scenario, phenotype
        )
        allowed = oracle if allowed is None else allowed & oracle
    partners = choose_partners(
        genome.tag,
        genome.selectivity,
        species,
        proto_ids,
        genome.tag[proto_index],
        elites,
        generator,
        allowed,
        always,
    )
    dominance = genome.dominance if cfg.dominance else torch.ones_like(genome.dominance)
    near = None
    if proto_distance is not None:
        pos = (species[:, None] == proto_ids).to(torch.int32).argmax(1)  # [P] species index
        near = cast(proto_distance, device=dev)[pos]  # [P, K]
    swarms = assemble_swarms(arange(P, dev), partners, dominance, S, generator, near)
    layouts = make_layouts(replace(scenario, num_robots=S), P * T, generator, dev)
    return EvalPlan(swarms, layouts, T)


def niche_partners(
    genome: Population,
    species: Tensor,
    proto_ids: Tensor,
    elites: Tensor,
    fitness: Tensor,
    has_fitness: Tensor,
    scenario: Scenario,
    phenotype: Phenotype | None = None,
) -> Tensor:
    """[K] bool: the species that may be partners under `partners_per_niche = "one"`
    (`partners.niche_representatives`), a species' capability being its fittest elite's.
    `phenotype`: the genome's, if computed."""
    k = proto_ids.numel()
    top = (
        elites[:, 0]
        if elites.shape[1]
        else torch.full((k,), -1, dtype=torch.long, device=species.device)
    )
    has_elite, first = top >= 0, top.clamp_min(0)
    ph = (
        Phenotype(*(t[first] for t in phenotype))
        if phenotype is not None
        else genome_phenotype(genome.index(first), scenario.hardware)
    )
    can = capabilities(ph, scenario, WorldParams.for_scenario(scenario))
    sizes = (species[:, None] == proto_ids[None, :]).sum(0)
    best = ranking_fitness(fitness, has_fitness)[first].masked_fill(~has_elite, -torch.inf)
    return niche_representatives(can, sizes, best, has_elite)


def sim_batch(plan: EvalPlan, genome: Population, lo: int = 0, hi: int | None = None) -> SimBatch:
    """Evaluations lo..hi of a plan as a SimBatch: the genome rows their teams use and the teams
    renumbered into them. The whole plan is the population and its teams as they are."""
    P, T = plan.size, plan.trials
    hi = P if hi is None else hi
    if lo == 0 and hi == P:
        return SimBatch(genome, plan.swarms.focal_team, plan.swarms.baseline_team, plan.layouts, T)
    focal, base = plan.swarms.focal_team[lo:hi], plan.swarms.baseline_team[lo:hi]
    teams = torch.cat([focal, base])
    rows = torch.unique(teams[teams >= 0])  # sorted
    local = [
        torch.where(t >= 0, torch.searchsorted(rows, t.clamp_min(0)), -1) for t in (focal, base)
    ]
    envs = torch.arange(lo * T, hi * T, device=plan.layouts.seed.device)
    return SimBatch(genome.index(rows), local[0], local[1], plan.layouts.select(envs), T)


def simulate_batch(
    batch: SimBatch,
    params: WorldParams,
    ticks: int,
    step_fn: StepFn | None = None,
    tables: Tensor | None = None,
    catalog: Catalog | None = None,
    phenotype: Phenotype | None = None,
) -> tuple[dict, float]:
    """Run a batch's focal and baseline teams over their trials in one rollout: per-environment
    metrics [2 * B * trials] (every focal trial, then every baseline trial, evaluation-major)
    and the rollout's wall time (device synchronised). `tables`: the behavior-tree tables of
    the batch's genome (default: built here); `catalog`: the scenario's hardware catalog;
    `phenotype`: the batch genome's (default: computed here)."""
    T, B = batch.trials, batch.focal_team.shape[0]
    dev = batch.genome.bt.device
    teams = torch.cat([batch.focal_team, batch.baseline_team]).repeat_interleave(T, 0)
    layout_ids = arange(B * T, dev).repeat(2)
    if tables is None:
        tables = bt.build_tables(batch.genome.bt)
    t0 = _now(dev)
    m = simulate_teams(
        teams,
        batch.genome,
        tables,
        layout_ids,
        batch.layouts,
        params,
        ticks,
        step_fn,
        catalog,
        phenotype,
    )
    return m, _now(dev) - t0


def gather_metrics(parts: list[dict]) -> dict:
    """The per-environment metrics of consecutive batches of a plan (`simulate_batch` of
    evaluations 0..a, a..b, ...) -> those of the whole plan, in the order `simulate_batch` of
    the whole plan returns them."""
    if len(parts) == 1:
        return parts[0]
    return {k: torch.cat([p[k].view(2, -1) for p in parts], 1).reshape(-1) for k in parts[0]}


def score_plan(
    plan: EvalPlan,
    genome: Population,
    m: dict,
    scenario: Scenario,
    cfg: EvalConfig,
    sim_seconds: float = 0.0,
    score_fn: ScoreFn = team_scores,
    phenotype: Phenotype | None = None,
) -> EvalResult:
    """Scores of a plan's evaluations from their per-environment metrics [2 * B * trials]:
    team cost, each team-episode's score (`score_fn`: F_raw times the budget penalty), the mean
    over trials, the marginal gate. `phenotype`: the genome's, if computed."""
    P, T = plan.size, plan.trials
    swarms = plan.swarms
    teams = torch.cat([swarms.focal_team, swarms.baseline_team])  # [2B, S]
    ph = phenotype if phenotype is not None else genome_phenotype(genome, scenario.hardware)
    counts = torch.cat([swarms.focal_species_count, swarms.baseline_species_count])
    # each team's cost, then each of its trials'
    costs = team_cost(ph.cost[teams.clamp_min(0)], teams >= 0, counts, scenario.species_overhead)
    cost = costs.repeat_interleave(T)
    focal, base = _scores(score_fn, m, cost, cfg).view(2, P, T).mean(-1).unbind()
    # every metric's mean over the focal team's trials, in one reduction
    means = torch.stack(list(m.values())).view(len(m), 2, P, T)[:, 0].mean(-1).unbind()
    team_m = dict(zip(m, means))
    return EvalResult(
        fitness=gate(focal, base, cfg.p_marginal),
        focal=focal,
        baseline=base,
        team_cost=costs[:P],
        swarms=swarms,
        team_metrics=team_m,
        sim_seconds=sim_seconds,
    )


def evaluate(
    plan: EvalPlan,
    genome: Population,
    scenario: Scenario,
    cfg: EvalConfig,
    params: WorldParams | None = None,
    step_fn: StepFn | None = None,
    tables: Tensor | None = None,
    evaluator=None,
    score_fn: ScoreFn = team_scores,
    phenotype: Phenotype | None = None,
) -> EvalResult:
    """Score every individual of the population by its marginal contribution to a team, from
    the `plan_evaluation` of the same genome, scenario and config (its teams and environments):
    the simulation, then `score_plan`. The simulation runs here (`simulate_batch` of the whole
    plan), or, given an `evaluator`, where its `simulate(plan, genome)` runs it
    (`distributed.ShardedEvaluator`: shards of whole evaluations on Ray actors), which returns
    the same per-environment metrics; `score_plan` then scores them here, each team-episode by
    `score_fn`. `phenotype`: the genome's (`population.genome_phenotype`), computed here if not
    given."""
    params = params or WorldParams.for_scenario(scenario)
    if phenotype is None:
        phenotype = genome_phenotype(genome, scenario.hardware)
    if evaluator is None:
        m, sim_seconds = simulate_batch(
            sim_batch(plan, genome),
            params,
            cfg.ticks,
            step_fn,
            tables,
            scenario.hardware,
            phenotype,
        )
    else:
        m, sim_seconds = evaluator.simulate(plan, genome)
    return score_plan(plan, genome, m, scenario, cfg, sim_seconds, score_fn, phenotype)


def _now(device: torch.device) -> float:
    """perf_counter() once the device has finished its queued work."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter()
