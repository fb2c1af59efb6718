"""Every algorithm on the same budget of team-episodes, their best teams scored on one common
set of held-out environments (`compare`), and the summary table."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import replace

import torch

from ..coevo.config import SwarmCoDeConfig
from ..coevo.dynamics import mean_std
from ..coevo.evolve import Context, make_context
from ..sim.layout import Layout
from ..sim.runtime import resolve_device
from .ccea import FixedSpeciesCCEA

#: Probability that an offspring of the GA / CCEA is a crossover child (else a clone of parent 1).
from .common import ALGORITHMS, HELD_OUT_SEED, FoundTeam, _Algorithm, new_layouts, score_teams
from .ga import HomogeneousGA
from .swarmcode import SwarmCoDeRun


def evaluate_team(best: FoundTeam, ctx: Context, layouts: Layout) -> dict:
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


def _run(name: str, cfg: SwarmCoDeConfig, num_species: int, ctx, held_out) -> dict:
    """One algorithm run for cfg.generations generations, its best team scored on the held-out
    environments: `compare`'s row."""
    t0 = time.perf_counter()
    algo = make_algorithm(name, cfg, num_species)
    last = None
    for _ in range(cfg.generations):
        last = algo.step()
    seconds = time.perf_counter() - t0
    ev = evaluate_team(algo.best, ctx, held_out)
    row = {
        "algorithm": name,
        "seed": cfg.seed,
        "generations": cfg.generations,
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
    return row


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
            rows.append(
                _run(
                    name,
                    replace(cfg0, seed=seed, generations=plan[name]),
                    num_species,
                    ctx,
                    held_out,
                )
            )
            if progress is not None:
                progress(rows[-1])
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
