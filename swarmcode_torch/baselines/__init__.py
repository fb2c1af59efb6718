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

from .ccea import FixedSpeciesCCEA, fixed_species_ccea
from .common import (
    ALGORITHMS,
    HELD_OUT_SEED,
    P_CROSSOVER,
    FoundTeam,
    distinct_per_row,
    new_layouts,
    reproduce_groups,
    score_teams,
    split_evenly,
)
from .compare import (
    SUMMARY_COLUMNS,
    compare,
    evaluate_team,
    make_algorithm,
    plan_generations,
    summarize,
)
from .ga import HomogeneousGA, homogeneous_ga
from .swarmcode import SwarmCoDeRun, swarmcode, swarmcode_no_dominance

__all__ = [
    "P_CROSSOVER",
    "HELD_OUT_SEED",
    "ALGORITHMS",
    "split_evenly",
    "distinct_per_row",
    "FoundTeam",
    "score_teams",
    "new_layouts",
    "reproduce_groups",
    "HomogeneousGA",
    "homogeneous_ga",
    "FixedSpeciesCCEA",
    "fixed_species_ccea",
    "SwarmCoDeRun",
    "swarmcode",
    "swarmcode_no_dominance",
    "evaluate_team",
    "plan_generations",
    "make_algorithm",
    "compare",
    "SUMMARY_COLUMNS",
    "summarize",
]
