"""`HomogeneousGA`: a plain generational GA over single designs; an individual's team is S clones
of itself (one species)."""

from __future__ import annotations

from collections.abc import Iterator

import torch
from torch import Tensor

from ..coevo.config import SwarmCoDeConfig

#: Probability that an offspring of the GA / CCEA is a crossover child (else a clone of parent 1).
from .common import _FixedPopulationAlgorithm


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


def homogeneous_ga(
    cfg: SwarmCoDeConfig, generations: int, generator: torch.Generator, **kw
) -> Iterator[dict]:
    """Run the homogeneous GA for `generations` generations, yielding each one's metrics."""
    algo = HomogeneousGA(cfg, generator, **kw)
    for _ in range(generations):
        yield algo.step()
