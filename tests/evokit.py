"""Short runs whose generations the share tests read: an `Evolution` stepped with a hook that
keeps every `AfterEvaluation` (state, speciation, evaluation, smoothed fitness)."""

from __future__ import annotations

from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.evolve import Evolution
from swarmcode_torch.coevo.hooks import Hooks


def evolve_seen(cfg: SwarmCoDeConfig, gens: int) -> tuple[Evolution, list]:
    """`gens` generations of `cfg`: the evolution and what its after-evaluation hook saw."""
    ev = Evolution(cfg)
    seen: list = []
    ev.hooks = Hooks(after_evaluation=[seen.append])
    for _ in range(gens):
        ev.step()
    return ev, seen
