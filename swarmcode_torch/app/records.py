"""A generation's `GenerationResult` as the run's records: the scalars under their TensorBoard
tags (also metrics.csv's columns and summary.json's `last_generation`), summary.json and the
teams.jsonl line. The only place that names the tags."""

from __future__ import annotations

import math
import platform
import subprocess
from dataclasses import replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import torch

from ..coevo.dynamics import niche_count
from ..coevo.evolve import BestTeam, Evolution, GenerationResult
from ..coevo.population import design_record, from_designs, genome_phenotype
from ..sim.hardware import Phenotype
from ..sim.state import WorldParams, capabilities
from . import best_team
from .run_record import app_record

#: The scalar tags of a generation, in the order of metrics.csv's columns.
SCALAR_TAGS = (
    "fitness/best",
    "fitness/mean",
    "species/count",
    "species/founded",
    "species/extinct",
    "species/median_age",
    "team/fitness",
    "team/fitness_reeval",
    "team/species",
    "team/niches",
    "team/median_age",
    "team/cost",
    "team/budget",
    "team/deliveries",
    "team/deliveries_individual",
    "team/deliveries_collab",
    "team/energy_used",
    "team/focal_max",
    "perf/generation_seconds",
    "perf/eval_seconds",
    "perf/sim_seconds",
    "perf/reeval_seconds",
)

#: The gene histograms of a generation: tag -> GenerationResult field. Named `traits/`: the
#: groups of TensorBoard's Time Series sort by name, so they come after `species/` and `team/`.
HISTOGRAMS = {
    "traits/radius": "radius",
    "traits/dominance": "dominance",
    "traits/selectivity": "selectivity",
}


def design_capabilities(designs, scenario) -> list[list[int]]:
    """For each summary / teams.jsonl design, the indices of the scenario's package classes it
    can lift (the `capability` the run recorded, or computed from its genes)."""
    if all("capability" in d for d in designs):
        return [list(d["capability"]) for d in designs]
    if not designs:
        return []
    genome, _ = from_designs(designs)
    return _capability_lists(genome_phenotype(genome, scenario.hardware), scenario)


def _capability_lists(ph: Phenotype, scenario) -> list[list[int]]:
    can = capabilities(ph, scenario, WorldParams.for_scenario(scenario))
    return [[j for j, ok in enumerate(row) if ok] for row in can.tolist()]


def team_record(team: BestTeam, generation: int, scenario) -> dict:
    """A generation's best team (`GenerationResult.best_team`) as its teams.jsonl record: the
    team's scores and its designs, most robots first, each with its capability (the
    scenario's package classes it can lift), and the team's niches, its distinct capabilities
    (`dynamics.niche_count`)."""
    host, caps = team.genome, _capability_lists(team.phenotype, scenario)
    # focal: the design of the focal individual; baseline_count: its robots in the baseline
    # team (the focal's slots refilled by its partners), which the replay page shows
    designs = [
        dict(
            design_record(host, i, s, c), count=n, focal=bool(f), baseline_count=nb, capability=cap
        )
        for i, (s, c, n, nb, f, cap) in enumerate(
            zip(
                team.species.tolist(),
                team.phenotype.cost.tolist(),
                team.count.tolist(),
                team.baseline_count.tolist(),
                team.focal.tolist(),
                caps,
            )
        )
    ]
    designs.sort(key=lambda d: -d["count"])
    tm = team.metrics
    return {
        "generation": generation,
        "fitness": team.fitness,
        "cost": team.cost,
        "species": len(designs),
        "deliveries_individual": tm["delivered_individual"],
        "deliveries_collab": tm["delivered_collab"],
        "deliveries": tm["delivered_individual"] + tm["delivered_collab"],
        "energy_used": tm["energy_used"],
        "designs": designs,
        "niches": niche_count(d["capability"] for d in designs),
    }


def describe_team(record: dict | None, scenario) -> dict | None:
    """Add to a team record written before records held them (a checkpoint's best team) each
    design's capability, the scenario's package classes it can lift, and the team's niches,
    its distinct capabilities (`dynamics.niche_count`). In place; a record that has them is
    left as it is."""
    if record is None or "niches" in record:
        return record
    designs = record.get("designs", [])
    for d, c in zip(designs, design_capabilities(designs, scenario)):
        d["capability"] = c
    record["niches"] = niche_count(d["capability"] for d in designs)
    return record


def step(ev: Evolution) -> GenerationResult:
    """One generation of `ev` with its report records: the generation's best team
    (`team_record`, re-evaluated on the run's `reeval_trials` fresh environments) and the run's
    best team so far, the one of the best re-evaluated mean (`best_team.update`), which
    `app_record(ev).best` keeps (a checkpoint saves it): what the application's reporters and
    callbacks receive."""
    result = ev.step()
    team = team_record(result.best_team, result.generation, ev.ctx.scenario)
    run = app_record(ev)
    run.best = describe_team(run.best, ev.ctx.scenario)
    best, seconds = best_team.update(ev, team)
    run.best = best
    return replace(result, team=team, best=best, reeval_seconds=seconds)


def scalars(r: GenerationResult) -> dict[str, Any]:
    """`generation` and every scalar of one generation under its tag (`SCALAR_TAGS` order): a
    row of metrics.csv, the TensorBoard scalars."""
    team = r.team
    return {
        "generation": r.generation,
        "fitness/best": r.best_fitness,
        "fitness/mean": r.mean_fitness,
        "species/count": r.num_species,
        "species/founded": r.founded,
        "species/extinct": r.extinct,
        "species/median_age": r.species_median_age,
        "team/fitness": team["fitness"],
        "team/fitness_reeval": team["reeval"]["mean"] if "reeval" in team else math.nan,
        "team/species": team["species"],
        "team/niches": team["niches"],
        "team/median_age": r.team_median_age,
        "team/cost": team["cost"],
        "team/budget": r.budget if r.budget is not None else math.nan,
        "team/deliveries": team["deliveries"],
        "team/deliveries_individual": team["deliveries_individual"],
        "team/deliveries_collab": team["deliveries_collab"],
        "team/energy_used": team["energy_used"],
        "team/focal_max": r.focal_max,
        "perf/generation_seconds": r.seconds,
        "perf/eval_seconds": r.eval_seconds,
        "perf/sim_seconds": r.sim_seconds,
        "perf/reeval_seconds": r.reeval_seconds,
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


@lru_cache(maxsize=1)
def git_commit() -> str | None:
    """The commit of the checkout the package runs from ('<sha>', '<sha>+dirty' with
    uncommitted changes to tracked files), or None for an installed package or without git."""
    root = Path(__file__).resolve().parents[2]
    if not (root / ".git").exists():
        return None
    try:
        sha = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
        )
        if sha.returncode or not sha.stdout.strip():
            return None
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return sha.stdout.strip() + ("+dirty" if dirty.returncode == 0 and dirty.stdout.strip() else "")


def device_name(device: torch.device | str) -> str:
    """'NVIDIA H200 (cuda:0)' for a GPU, 'cpu (x86_64)' for the CPU."""
    dev = torch.device(device)
    if dev.type == "cuda":
        return f"{torch.cuda.get_device_name(dev)} ({dev})"
    return f"{dev.type} ({platform.machine() or 'unknown'})"


def software(device: torch.device | str) -> dict:
    """What made a run's files: package and torch versions, the device and the git commit (None
    outside a checkout); summary.json's "software", config.toml's "written by" comment."""
    from ..sim.runtime import resolve_device
    from ..version import __version__

    try:
        name = device_name(resolve_device(device) if isinstance(device, str) else device)
    except (RuntimeError, ValueError, AssertionError):
        name = str(device)
    return {
        "swarmcode-torch": __version__,
        "torch": torch.__version__,
        "device": name,
        "commit": git_commit(),
    }


def summary(ev: Evolution, r: GenerationResult) -> dict:
    """The contents of summary.json after a generation."""
    best = r.best
    return json_clean(
        {
            "generation": r.generation,
            "generations": ev.cfg.generations,
            "scenario": ev.cfg.scenario,
            "objective": ev.cfg.objective,
            "preset": ev.cfg.preset,
            # the best team's re-evaluated mean (its single evaluation without re-evaluation)
            "best_fitness": best["fitness"],
            "best_generation": best["generation"],
            **best_team.summary_fields(best),
            "team_cost": best["cost"],
            "budget": ev.cfg.budget,
            "num_species": best["species"],
            "niches": best.get("niches"),
            "deliveries": best["deliveries"],
            "deliveries_individual": best["deliveries_individual"],
            "deliveries_collab": best["deliveries_collab"],
            "energy_used": best["energy_used"],
            "species_in_population": r.num_species,
            "device": str(ev.ctx.device),
            "tick": ev.ctx.tick_mode,
            "software": software(ev.ctx.device),
            "designs": best["designs"],
            "last_generation": {k: v for k, v in scalars(r).items() if k != "generation"},
            # only a run scored by a user function says so (the built-in is the paper's fitness)
            **(
                {"fitness": f"custom: {ev.cfg.fitness_function}"}
                if ev.cfg.fitness_function is not None
                else {}
            ),
        }
    )


def team_line(r: GenerationResult) -> dict:
    """The generation's best team as its teams.jsonl record."""
    return json_clean(r.team)
