"""The explorer (`refound_source = "random"`, `coevo.refound`): the best individual's tree with
hardware drawn as generation 0 draws it, put in every `refound_after` generations under the
re-founding trial; the archive untouched; a whole run repeats itself."""

from __future__ import annotations

from dataclasses import fields, replace
from functools import partial

import pytest
import torch
from evokit import assert_changes_and_repeats

from swarmcode_torch.coevo import refound
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.evolve import Evolution, random_population
from swarmcode_torch.coevo.population import GENE_BOUNDS, GENE_VALUES, Population
from swarmcode_torch.coevo.reproduction import mutate

CFG = SwarmCoDeConfig()
HARDWARE = ("radius", "chassis", "battery", "motor", "torque_point", "battery_point", "effector")
KEPT = ("tag", "selectivity", "dominance", "bt")


def _pop(n: int, seed: int) -> Population:
    return random_population(n, CFG, torch.Generator().manual_seed(seed), torch.device("cpu"))


def test_random_hardware_keeps_the_tree_and_tag_and_draws_one_design_for_every_row():
    assert {f.name for f in fields(Population)} == set(HARDWARE) | set(KEPT)
    base = _pop(4, 0)
    out = refound.random_hardware(base, torch.Generator().manual_seed(7))
    for name in KEPT:
        assert torch.equal(getattr(out, name), getattr(base, name))
    for name in HARDWARE:
        v = getattr(out, name)
        assert (v == v[0]).all()  # one design
        if name in GENE_BOUNDS:
            lo, hi = GENE_BOUNDS[name]
            assert lo <= float(v[0]) <= hi
        else:
            assert 0 <= int(v[0]) < GENE_VALUES[name]
    # the numbers drawn do not depend on what the rows hold
    other = refound.random_hardware(_pop(4, 1), torch.Generator().manual_seed(7))
    for name in HARDWARE:
        assert torch.equal(getattr(other, name), getattr(out, name))
    assert refound.explorer("partners", torch.Generator()) is None
    assert refound.explorer("designs", torch.Generator()) is None


def _archive(n: int) -> refound.Archive:
    genome = _pop(n, 2)
    species = torch.arange(n)
    fit = torch.arange(float(n))
    partner = torch.ones(n, dtype=torch.bool)
    arc = refound.champions(None, genome, fit, species, species, partner, n, 0)
    arc = refound.champions(arc, genome, fit, species, species, partner, n, 6)  # 6 generations old
    # species 0 dies a partner at generation 6: one archived champion, due for re-founding
    return refound.observe(arc, species, species[1:], n, n, 6)


def _inject(arc, gen: int, explore):
    children = _pop(8, 3)
    hint = torch.arange(8)
    parent_fitness = torch.tensor([5.0, 1.0, 9.0, 2.0, 0.5, 3.0, 0.1, 4.0])
    is_elite = torch.tensor([True, False, True, False, False, False, False, False])
    g = torch.Generator().manual_seed(11)
    out = refound.inject(
        arc,
        children,
        hint,
        parent_fitness,
        is_elite,
        gen,
        5,
        partial(mutate, params=CFG.reproduction, generator=g),
        explore=explore,
    )
    return children, out


def test_the_explorer_copies_the_best_elite_child_with_new_hardware_every_after_generations():
    arc = _archive(4)
    assert int((arc.died >= 0).sum()) == 1
    g = torch.Generator().manual_seed(5)
    # the archive's entry (dead at 6) is due from generation 11 on: the explorer ignores it
    for gen, due in ((11, False), (15, True), (17, False), (20, True)):
        children, (out, kids, hint) = _inject(arc, gen, refound.explorer("random", g))
        assert bool(out.injected) == due
        # the archive is not read: its entry stays, due or not
        assert torch.equal(out.died, arc.died)
        rows = out.injected_rows
        # the offspring of the three least fit parents that are not elites: rows 6, 4, 1
        assert rows.tolist() == [6, 4, 1]
        if not due:
            assert all(
                torch.equal(a, b)
                for a, b in zip(kids.state_dict().values(), children.state_dict().values())
            )
            assert torch.equal(hint, torch.arange(8))
            continue
        first = kids.index(rows[:1])
        # the tree and tag of the best elite child (row 2, parent fitness 9)
        assert torch.equal(first.bt[0], children.bt[2]) and torch.equal(
            first.tag[0], children.tag[2]
        )
        assert float(first.radius[0]) != float(children.radius[2])  # drawn again
        assert (hint[rows] == -1).all()
        others = torch.tensor([r for r in range(8) if r not in rows.tolist()])
        assert torch.equal(kids.bt[others], children.bt[others])


SMALL = replace(CFG, scenario="two-niche", population=24, trials=1, ticks=40, seed=3)


def test_a_run_with_the_explorer_founds_trial_species_changes_the_run_and_repeats():
    ev = Evolution(replace(SMALL, refound_after=3, refound_source="random"))
    founded_on_trial = 0
    for _ in range(8):
        ev.step()
        arc = ev.state.archive
        founded_on_trial = max(founded_on_trial, int((arc.trial_until >= 0).sum()))
    assert founded_on_trial >= 1  # an explorer founded a species that got the trial floor
    assert_changes_and_repeats(SMALL, 7, refound_after=3, refound_source="random")
    with pytest.raises(ValueError, match="refound_source"):
        replace(SMALL, refound_source="randomly").validate()
