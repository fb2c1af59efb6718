"""Re-founding by design cell (`refound_source = "designs"`, `coevo.refound`): which champions
are archived, one entry per cell, re-founding only into an empty cell, a whole run."""

from __future__ import annotations

from dataclasses import replace
from functools import partial

import pytest
import torch

from swarmcode_torch.coevo import refound
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.evolve import Evolution
from swarmcode_torch.coevo.population import Population
from swarmcode_torch.coevo.reproduction import mutate
from swarmcode_torch.sim.hardware import R_MAX, R_MIN

CFG = SwarmCoDeConfig()
BINS = refound.REFOUND.size_bins
WIDTH = (R_MAX - R_MIN) / BINS


def _designs(effector: list[int], band: list[int], seed: int = 0) -> Population:
    """Random genomes whose effector and radius band are the given ones (radius mid-band)."""
    from swarmcode_torch.coevo.evolve import random_population

    n = len(effector)
    pop = random_population(n, CFG, torch.Generator().manual_seed(seed), torch.device("cpu"))
    radius = R_MIN + (torch.tensor(band, dtype=torch.float) + 0.5) * WIDTH
    return replace(pop, effector=torch.tensor(effector), radius=radius.to(pop.radius.dtype))


def _same(a: Population, b: Population) -> bool:
    return all(torch.equal(x, y) for x, y in zip(a.state_dict().values(), b.state_dict().values()))


def test_design_cell_is_effector_then_radius_band_with_the_range_ends_inside():
    pop = _designs([0, 0, 1, 1], [0, BINS - 1, 0, 1])
    assert refound.design_cell(pop, BINS).tolist() == [0, BINS - 1, BINS, BINS + 1]
    ends = replace(pop, radius=torch.tensor([R_MIN, R_MAX, R_MAX, R_MIN], dtype=pop.radius.dtype))
    assert refound.design_cell(ends, BINS).tolist() == [0, BINS - 1, 2 * BINS - 1, BINS]


def _champions(genome: Population, species: torch.Tensor, gen: int, arc=None):
    ids = torch.unique(species)
    fit = torch.arange(float(genome.size))  # the last row of each species is its champion
    return refound.champions(
        arc, genome, fit, species, ids, None, int(ids.max()) + 1, gen, bins=BINS
    )


def test_only_the_sole_champion_of_a_cell_is_archivable_at_any_age():
    # species 0 and 1 share cell (suction, band 0); species 2 is alone in (pincher, band 2)
    genome = _designs([0, 0, 1], [0, 0, 2])
    arc = _champions(genome, torch.tensor([0, 1, 2]), gen=0)
    assert arc.champ_partner.tolist() == [False, False, True]  # generation 0: no minimum age


def test_a_dead_sole_holder_is_archived_over_an_entry_of_its_cell():
    genome = _designs([1, 0, 0], [2, 0, 1])
    species = torch.tensor([0, 1, 2])
    arc = _champions(genome, species, gen=0)
    # species 0 (pincher, band 2) dies at generation 1: archived
    arc = refound.observe(arc, species, torch.tensor([1, 2]), 3, 3, 1, bins=BINS)
    assert (arc.died >= 0).sum() == 1 and int(arc.died[0]) == 1
    # a new species 3 of the same cell is founded, then dies at generation 5: it takes the same
    # slot, not a second one
    later = _designs([1, 0, 0], [2, 0, 1], seed=5)
    arc = _champions(later, torch.tensor([3, 1, 2]), gen=4, arc=arc)
    arc = refound.observe(arc, torch.tensor([1, 1, 2]), torch.tensor([1, 2]), 4, 4, 5, bins=BINS)
    assert (arc.died >= 0).sum() == 1 and int(arc.died[0]) == 5
    assert _same(arc.genome.index(torch.tensor([0])), later.index(torch.tensor([0])))


def test_two_dead_holders_of_different_cells_take_two_slots():
    genome = _designs([1, 0, 0], [2, 0, 1])
    species = torch.tensor([0, 1, 2])
    arc = _champions(genome, species, gen=0)
    arc = refound.observe(
        arc, torch.zeros(3, dtype=torch.long), torch.tensor([2]), 3, 3, 1, bins=BINS
    )
    assert sorted(arc.died.tolist())[-2:] == [1, 1] and int((arc.died >= 0).sum()) == 2


def _inject(arc, gen: int):
    n = 9
    children = _designs([0] * n, [0] * n, seed=3)
    g = torch.Generator().manual_seed(1)
    return refound.inject(
        arc,
        children,
        torch.arange(n),
        torch.arange(float(n)),
        torch.zeros(n, dtype=torch.bool),
        gen,
        2,
        partial(mutate, params=CFG.reproduction, generator=g),
        bins=BINS,
    )


def test_an_entry_waits_while_a_living_champion_holds_its_cell():
    genome = _designs([1, 0], [2, 0])
    arc = _champions(genome, torch.tensor([0, 1]), gen=0)
    arc = refound.observe(arc, torch.tensor([1, 1]), torch.tensor([1]), 2, 2, 1, bins=BINS)
    # a new species 2 now holds (pincher, band 2) again: the entry waits
    held = _champions(_designs([1, 0], [2, 0], seed=9), torch.tensor([2, 1]), gen=5, arc=arc)
    out, _, _ = _inject(held, 5)
    assert not bool(out.injected) and int((out.died >= 0).sum()) == 1
    # the cell empty again: its copies go in, the entry leaves the archive
    empty = _champions(_designs([0, 0], [0, 1], seed=9), torch.tensor([1, 3]), gen=6, arc=arc)
    out, kids, hint = _inject(empty, 6)
    assert bool(out.injected) and int((out.died >= 0).sum()) == 0
    assert _same(kids.index(out.injected_rows[:1]), genome.index(torch.tensor([0])))
    assert (hint[out.injected_rows] == -1).all()


SMALL = replace(CFG, scenario="four-niche", population=24, trials=1, ticks=40, seed=3)


def test_a_run_with_design_refounding_differs_from_partner_refounding_and_is_checked():
    assert CFG.refound_source == "partners"
    designs = Evolution(replace(SMALL, refound_after=2, refound_source="designs"))
    partners = Evolution(replace(SMALL, refound_after=2))
    for _ in range(8):
        designs.step()
        partners.step()
    arc = designs.state.archive
    assert arc is not None
    cells = refound.design_cell(arc.champ, BINS)
    # archivable: exactly the champions alone in their cell
    alone = (cells[:, None] == cells[None, :]).sum(1) == 1
    assert torch.equal(arc.champ_partner, alone)
    with pytest.raises(ValueError, match="refound_source"):
        replace(SMALL, refound_source="niches").validate()
