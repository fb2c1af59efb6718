"""A generation's `GenerationResult` as the run's records: the scalars under their TensorBoard
tags (also metrics.csv's columns and summary.json's `last_generation`), summary.json and the
teams.jsonl line. The only place that names the tags."""

from __future__ import annotations

import math
from typing import Any

from ..coevo.evolve import Evolution, GenerationResult

#: The scalar tags of a generation, in the order of metrics.csv's columns.
SCALAR_TAGS = (
    "fitness/best", "fitness/mean", "species/count", "species/founded", "species/extinct",
    "species/median_age", "team/fitness", "team/species", "team/niches", "team/median_age",
    "team/cost",
    "team/budget", "team/deliveries", "team/deliveries_individual", "team/deliveries_collab",
    "team/energy_used", "team/focal_max", "perf/generation_seconds", "perf/eval_seconds", "perf/sim_seconds",
)

#: The gene histograms of a generation: tag -> GenerationResult field.
HISTOGRAMS = {"hist/radius": "radius", "hist/dominance": "dominance",
              "hist/selectivity": "selectivity"}


def scalars(r: GenerationResult) -> dict[str, Any]:
    """`generation` and every scalar of one generation under its tag (`SCALAR_TAGS` order): a
    row of metrics.csv, the TensorBoard scalars."""
    team = r.team
    return {
        "generation": r.generation,
        "fitness/best": r.best_fitness, "fitness/mean": r.mean_fitness,
        "species/count": r.num_species, "species/founded": r.founded,
        "species/extinct": r.extinct, "species/median_age": r.species_median_age,
        "team/fitness": team["fitness"], "team/species": team["species"],
        "team/niches": team["niches"], "team/median_age": r.team_median_age,
        "team/cost": team["cost"],
        "team/budget": r.budget if r.budget is not None else math.nan,
        "team/deliveries": team["deliveries"],
        "team/deliveries_individual": team["deliveries_individual"],
        "team/deliveries_collab": team["deliveries_collab"],
        "team/energy_used": team["energy_used"], "team/focal_max": r.focal_max,
        "perf/generation_seconds": r.seconds, "perf/eval_seconds": r.eval_seconds,
        "perf/sim_seconds": r.sim_seconds,
    }


def json_clean(x: Any) -> Any:
    """A JSON-friendly copy: NaN and infinities as null, keys as strings."""
    if isinstance(x, dict):
        return {str(k): json_clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_clean(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def summary(ev: Evolution, r: GenerationResult) -> dict:
    """The contents of summary.json after a generation."""
    best = r.best
    return json_clean({
        "generation": r.generation, "generations": ev.cfg.generations,
        "scenario": ev.cfg.scenario, "objective": ev.cfg.objective,
        "best_fitness": best["fitness"], "best_generation": best["generation"],
        "team_cost": best["cost"], "budget": ev.cfg.budget, "num_species": best["species"],
        "niches": best.get("niches"),
        "deliveries": best["deliveries"],
        "deliveries_individual": best["deliveries_individual"],
        "deliveries_collab": best["deliveries_collab"], "energy_used": best["energy_used"],
        "species_in_population": r.num_species,
        "device": str(ev.ctx.device), "tick": ev.ctx.tick_mode,
        "designs": best["designs"],
        "last_generation": {k: v for k, v in scalars(r).items() if k != "generation"},
        # only a run scored by a user function says so (the built-in is the paper's fitness)
        **({"fitness": f"custom: {ev.cfg.fitness_function}"}
           if ev.cfg.fitness_function is not None else {}),
    })


def team_line(r: GenerationResult) -> dict:
    """The generation's best team as its teams.jsonl record."""
    return json_clean(r.team)
