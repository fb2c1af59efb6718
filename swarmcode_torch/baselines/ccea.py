"""`FixedSpeciesCCEA`: cooperative co-evolution (Potter & De Jong) with K subpopulations fixed in
advance, each owning a fixed share of the S team slots."""

from __future__ import annotations

from collections.abc import Iterator

import torch
from torch import Tensor

from ..coevo.config import SwarmCoDeConfig

#: Probability that an offspring of the GA / CCEA is a crossover child (else a clone of parent 1).
from .common import _FixedPopulationAlgorithm, split_evenly


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


def fixed_species_ccea(
    cfg: SwarmCoDeConfig, num_species: int, generations: int, generator: torch.Generator, **kw
) -> Iterator[dict]:
    """Run the K-species CCEA for `generations` generations, yielding each one's metrics."""
    algo = FixedSpeciesCCEA(cfg, num_species, generator, **kw)
    for _ in range(generations):
        yield algo.step()
