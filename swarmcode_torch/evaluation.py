"""Evaluation of a whole population in one simulator batch (paper: "Evaluation and Fitness").

Every individual gets a focal team (itself, one elite of each partner species, dominance-sampled
clones) and a baseline team (its slots refilled from the partners), each run over the same
`trials` random environments. All focal and baseline trials of a generation are one batch of
E = 2 * B * trials environments through one tick loop.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Callable

import torch
from torch import Tensor

from . import bt
from .fitness import FitnessWeights, budget_penalty, gate, raw_fitness, team_cost
from .genome import Genome
from .hardware import genome_phenotype
from .layout import Layout, make_layouts
from .partners import Swarms, assemble_swarms, choose_partners, elite_rows
from .reproduction import elite_count
from .scenario import Scenario
from .world import Robots, WorldParams, rollout

StepFn = Callable


@dataclass(frozen=True)
class EvalConfig:
    """How teams are built and scored."""

    swarm_size: int = 20            # robots per team
    trials: int = 3                 # random environments per team (focal and baseline share them)
    ticks: int = 250                # episode length
    budget: float | None = None     # $; None: no budget penalty
    objective: str = "fitness"      # "fitness" or "roi" (fitness divided by team cost)
    lam: float = 0.001              # budget penalty decay
    p_marginal: float = 0.25        # factor on fitness when the marginal contribution is <= 0
    max_elite: int = 3              # E in the elite count (partner elites are drawn from these)
    dominance: bool = True          # False: uniform team composition (an ablation)
    evaluated_partners: bool = False  # partners are elites with a fitness (none from a new species)
    weights: FitnessWeights = FitnessWeights()


@dataclass(frozen=True, eq=False)
class EvalResult:
    """Scores of B evaluated individuals, and everything about their focal teams."""

    fitness: Tensor        # [B] gated fitness of each individual (before EMA smoothing)
    focal: Tensor          # [B] focal team score (mean over trials)
    baseline: Tensor       # [B] baseline team score
    team_cost: Tensor      # [B] focal team cost ($)
    swarms: Swarms         # team compositions (population rows per slot)
    team_metrics: dict     # name -> [B] focal team episode metrics, mean over trials
    sim_seconds: float = 0.0  # wall time of the rollout alone (device synchronised)


def team_scores(metrics: dict, cost: Tensor, cfg: EvalConfig) -> Tensor:
    """[E] score of each team-episode: F_raw times the budget penalty (divided by cost for ROI)."""
    f = raw_fitness(metrics, cfg.weights) * budget_penalty(cost, cfg.budget, cfg.lam)
    if cfg.objective == "roi":
        f = f / cost.clamp_min(1.0)
    return f


def team_robots(genome: Genome, teams: Tensor) -> Robots:
    """Per-robot constants of teams [E, S] of population rows (-1: an empty slot); each robot
    runs its row's program (row of `bt.build_tables(genome.bt)`)."""
    ph = genome_phenotype(genome)
    rows = teams.clamp_min(0)
    return Robots(*(t[rows] for t in (ph.radius, ph.mass, ph.force, ph.payload, ph.capacity,
                                        ph.efficiency, ph.effector)),
                  present=teams >= 0, program=rows)


def simulate_teams(teams: Tensor, genome: Genome, tables: Tensor, layout_ids: Tensor,
                   layouts: Layout, params: WorldParams, ticks: int,
                   step_fn: StepFn | None = None) -> dict:
    """Run teams [E, S] (population rows, -1 empty) in layouts[layout_ids]; metrics [E] each."""
    return rollout(layouts.index(layout_ids), team_robots(genome, teams), tables, params, ticks,
                   step_fn)


def evaluate(genome: Genome, species: Tensor, proto_ids: Tensor, proto_index: Tensor,
             fitness: Tensor, has_fitness: Tensor, scenario: Scenario, cfg: EvalConfig,
             generator: torch.Generator, params: WorldParams | None = None,
             step_fn: StepFn | None = None, tables: Tensor | None = None) -> EvalResult:
    """Score every individual of the population by its marginal contribution to a team."""
    P = genome.size
    dev = genome.bt.device
    params = params or WorldParams.for_scenario(scenario)
    S, T = cfg.swarm_size, cfg.trials

    # --- composition: partners by tag and selectivity, slots by dominance
    elites = elite_rows(fitness, has_fitness, species, proto_ids,
                        lambda n: elite_count(n, cfg.max_elite), cfg.evaluated_partners)
    partners = choose_partners(genome.tag, genome.selectivity, species, proto_ids,
                               genome.tag[proto_index], elites, generator)
    dominance = genome.dominance if cfg.dominance else torch.ones_like(genome.dominance)
    swarms = assemble_swarms(torch.arange(P, device=dev), partners, dominance, S, generator)

    # --- one batch: [focal teams x trials ; baseline teams x trials], sharing layouts
    layouts = make_layouts(replace(scenario, num_robots=S), P * T, generator, dev)
    teams = torch.cat([swarms.focal_team, swarms.baseline_team]).repeat_interleave(T, 0)
    layout_ids = torch.arange(P * T, device=dev).repeat(2)
    if tables is None:
        tables = bt.build_tables(genome.bt)
    t0 = _now(dev)
    m = simulate_teams(teams, genome, tables, layout_ids, layouts, params, cfg.ticks, step_fn)
    sim_seconds = _now(dev) - t0

    # --- scores
    robot_cost = genome_phenotype(genome).cost[teams.clamp_min(0)]
    counts = torch.cat([swarms.focal_species_count, swarms.baseline_species_count]).repeat_interleave(T)
    cost = team_cost(robot_cost, teams >= 0, counts, scenario.species_overhead)
    score = team_scores(m, cost, cfg).view(2, P, T).mean(-1)
    focal, base = score[0], score[1]
    team_m = {k: v.view(2, P, T)[0].mean(-1) for k, v in m.items()}
    return EvalResult(fitness=gate(focal, base, cfg.p_marginal), focal=focal, baseline=base,
                      team_cost=cost.view(2, P, T)[0, :, 0], swarms=swarms, team_metrics=team_m,
                      sim_seconds=sim_seconds)


def _now(device: torch.device) -> float:
    """perf_counter() once the device has finished its queued work."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter()
