"""`SwarmCoDeRun`: SwarmCoDe (`evolve.Evolution`) behind the baselines' interface, and its
dominance-disabled ablation."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

from ..coevo.config import SwarmCoDeConfig
from ..coevo.evolve import Evolution, GenerationResult

#: Probability that an offspring of the GA / CCEA is a crossover child (else a clone of parent 1).
from .common import FoundTeam, _Algorithm, _team_of


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

        def build() -> FoundTeam:
            return _team_of(genome, m.team_rows, team.fitness, team.cost, gen)

        self._offer(build, team.fitness)
        out = self._metrics(team.fitness, int(team.rows.numel()), m.mean_fitness, m.seconds)
        out["species/count"] = m.num_species
        return out


# ------------------------------------------------------------------ generator-style API
def swarmcode(cfg: SwarmCoDeConfig, generations: int) -> Iterator[dict]:
    """Run SwarmCoDe for `generations` generations, yielding each one's metrics."""
    algo = SwarmCoDeRun(replace(cfg, generations=generations))
    for _ in range(generations):
        yield algo.step()


def swarmcode_no_dominance(cfg: SwarmCoDeConfig, generations: int) -> Iterator[dict]:
    """SwarmCoDe with uniform team composition (dominance genes ignored)."""
    return swarmcode(replace(cfg, dominance=False), generations)


# ------------------------------------------------------------------ comparison
