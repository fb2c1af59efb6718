"""Short runs whose generations the share tests read: an `Evolution` stepped with a hook that
keeps every `AfterEvaluation` (state, speciation, evaluation, smoothed fitness)."""

from __future__ import annotations

from dataclasses import replace

import torch

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


def assert_changes_and_repeats(cfg: SwarmCoDeConfig, gens: int, **setting) -> None:
    """`gens` generations of `cfg` with `setting` differ from those without it (the smoothed
    fitness), and a second run with it repeats the first (fitness, species, partners)."""
    a, _ = evolve_seen(cfg, gens)
    on = replace(cfg, **setting)
    b, _ = evolve_seen(on, gens)
    c, _ = evolve_seen(on, gens)
    assert not torch.equal(a.state.fitness, b.state.fitness)
    assert torch.equal(b.state.fitness, c.state.fitness)
    assert torch.equal(b.state.species_hint, c.state.species_hint)
    if b.state.admission is not None:
        assert torch.equal(b.state.admission.partner, c.state.admission.partner)
