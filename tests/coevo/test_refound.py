"""Re-founding extinct partner species (`coevo.refound`): the archive, the copies, the trial
floor, checkpoints."""

from __future__ import annotations

from dataclasses import replace
from functools import partial

import pytest
import torch

from swarmcode_torch.coevo import refound
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.evolve import Evolution, load_state_dict, random_population, state_dict
from swarmcode_torch.coevo.population import Population
from swarmcode_torch.coevo.reproduction import mutate

CFG = SwarmCoDeConfig()


def _pop(n: int, seed: int = 0) -> Population:
    return random_population(n, CFG, torch.Generator().manual_seed(seed), torch.device("cpu"))


def _same(a: Population, b: Population) -> bool:
    return all(torch.equal(x, y) for x, y in zip(a.state_dict().values(), b.state_dict().values()))


def _started(genome: Population, species: torch.Tensor, fit: torch.Tensor, useful, gen: int):
    ids = torch.unique(species)
    return refound.champions(None, genome, fit, species, ids, useful, int(ids.max()) + 1, gen)


def test_champion_is_each_species_fittest_member_first_row_on_ties():
    genome = _pop(6)
    species = torch.tensor([0, 1, 0, 1, 2, 0])
    fit = torch.tensor([1.0, 5.0, 3.0, 5.0, 0.5, 3.0])
    arc = _started(genome, species, fit, torch.ones(3, dtype=torch.bool), 0)
    assert _same(arc.champ, genome.index(torch.tensor([2, 1, 4])))
    assert arc.champ_ids.tolist() == [0, 1, 2]
    assert (arc.died == -1).all() and arc.died.numel() == refound.REFOUND.capacity


def test_only_dead_partners_of_min_age_are_archived():
    genome = _pop(6)
    species = torch.tensor([0, 1, 2, 0, 1, 2])
    fit = torch.arange(6.0)
    age = refound.REFOUND.min_age
    # species 0..2 founded at generation 0; champions read at generation `age`
    arc = _started(genome, species, fit, torch.ones(3, dtype=torch.bool), 0)
    useful = torch.tensor([True, False, True])
    arc = refound.champions(arc, genome, fit, species, torch.arange(3), useful, 3, age)
    assert arc.champ_partner.tolist() == [True, False, True]
    # at generation age + 1, species 1 and 2 are gone: only 2 (a partner) is archived
    arc = refound.observe(arc, torch.zeros(6, dtype=torch.long), torch.tensor([0]), 3, 3, age + 1)
    alive = arc.died >= 0
    assert int(alive.sum()) == 1 and int(arc.died[alive]) == age + 1
    assert _same(arc.genome.index(alive.nonzero()[0]), genome.index(torch.tensor([5])))
    # a partner younger than min_age is not archived
    young = _started(genome, species, fit, torch.ones(3, dtype=torch.bool), 0)
    young = refound.champions(young, genome, fit, species, torch.arange(3), useful, 3, age - 1)
    assert young.champ_partner.tolist() == [False, False, False]


def test_full_archive_replaces_its_oldest_entries():
    c = refound.REFOUND.capacity
    genome = _pop(c + 2)
    species = torch.arange(c + 2)
    fit = torch.ones(c + 2)
    arc = _started(genome, species, fit, torch.ones(c + 2, dtype=torch.bool), 0)
    arc = replace(arc, died=torch.arange(c) + 100)  # full, oldest: slot 0
    arc = refound.champions(
        arc, genome, fit, species, species, torch.ones(c + 2, dtype=torch.bool), c + 2, 10
    )
    # species c and c + 1 die at generation 200
    arc = refound.observe(
        arc, torch.zeros(c + 2, dtype=torch.long), torch.arange(c), c + 2, c + 2, 200
    )
    assert arc.died.tolist()[:2] == [200, 200]
    assert arc.died.tolist()[2:] == list(range(102, 100 + c))


def _with_entry(n: int, died: int) -> tuple[refound.Archive, Population]:
    genome = _pop(n)
    species = torch.arange(n) % 3
    arc = _started(genome, species, torch.ones(n), torch.ones(3, dtype=torch.bool), 0)
    entry = _pop(1, seed=7)
    slot0 = torch.arange(arc.died.numel()) == 0
    arc = replace(
        arc,
        genome=entry.index(torch.zeros(arc.died.numel(), dtype=torch.long)),
        died=torch.where(slot0, died, -1),
    )
    return arc, entry


def test_inject_copies_the_due_entry_into_the_least_fit_parents_offspring():
    n, m = 12, refound.REFOUND.clones
    arc, entry = _with_entry(n, died=10)
    children = _pop(n, seed=3)
    hint = torch.arange(n)
    parent_fit = torch.tensor([9.0, 1.0, 2.0, 0.5, 8.0, 7.0, 6.0, 5.0, 4.0, 3.0, 0.1, 0.2])
    is_elite = torch.zeros(n, dtype=torch.bool)
    is_elite[10] = True  # an elite is never replaced
    g = torch.Generator().manual_seed(1)
    mut = partial(mutate, params=CFG.reproduction, generator=g)
    out, kids, h = refound.inject(arc, children, hint, parent_fit, is_elite, 15, 5, mut)
    rows = [11, 3, 1]  # the least fit parents but the elite
    assert sorted(out.injected_rows.tolist()) == sorted(rows) and bool(out.injected)
    assert _same(kids.index(torch.tensor([11])), entry)  # the first copy is exact
    assert (h[rows] == -1).all() and h.tolist()[:1] == [0]
    others = [i for i in range(n) if i not in rows]
    assert _same(kids.index(torch.tensor(others)), children.index(torch.tensor(others)))
    assert int(out.died[0]) == -1 and int(out.injected_tries) == 1 and m == 3


def test_inject_before_due_changes_nothing_but_draws_the_same():
    n = 12
    arc, _ = _with_entry(n, died=10)
    children = _pop(n, seed=3)
    args = (
        children,
        torch.arange(n),
        torch.arange(n, dtype=torch.float),
        torch.zeros(n, dtype=bool),
    )
    g1, g2 = torch.Generator().manual_seed(1), torch.Generator().manual_seed(1)
    out, kids, h = refound.inject(
        arc, *args, 14, 5, partial(mutate, params=CFG.reproduction, generator=g1)
    )
    assert not bool(out.injected) and int(out.died[0]) == 10
    assert _same(kids, children) and torch.equal(h, torch.arange(n))
    refound.inject(arc, *args, 15, 5, partial(mutate, params=CFG.reproduction, generator=g2))
    assert torch.equal(g1.get_state(), g2.get_state())  # the stream does not depend on the archive


def test_a_species_founded_by_copies_keeps_a_trial_floor():
    n = 12
    arc, _ = _with_entry(n, died=10)
    arc = replace(
        arc,
        injected_rows=torch.tensor([4, 5, 6]),
        injected=torch.tensor(True),
        injected_tries=torch.tensor(1),
    )
    species = torch.tensor([0, 1, 2, 0, 3, 3, 1, 2, 0, 1, 2, 0])  # copies 4, 5 founded id 3
    arc = refound.observe(arc, species, torch.arange(4), 3, 4, 20)
    trial = refound.REFOUND.trial
    assert arc.trial_until.tolist() == [-1, -1, -1, 20 + trial - 1]
    assert arc.lineage.tolist() == [0, 0, 0, 1] and int(arc.born[3]) == 20
    assert refound.on_trial(arc, torch.arange(4), 20 + trial - 1).tolist() == [0, 0, 0, 1]
    assert refound.on_trial(arc, torch.arange(4), 20 + trial).tolist() == [0, 0, 0, 0]


def _run(cfg: SwarmCoDeConfig, gens: int, ev: Evolution | None = None) -> Evolution:
    ev = ev or Evolution(cfg)
    for _ in range(gens):
        ev.step()
    return ev


SMALL = replace(CFG, scenario="four-niche", population=24, trials=1, ticks=40, seed=3)


def test_off_by_default_and_on_it_keeps_state_through_a_checkpoint():
    assert _run(SMALL, 3).state.archive is None
    cfg = replace(SMALL, refound_after=2)
    whole = _run(cfg, 8)
    assert whole.state.archive is not None
    half = _run(cfg, 4)
    d = state_dict(half.state, half.cfg)
    back = Evolution.from_checkpoint(d, cfg)
    _run(cfg, 4, back)
    a, b = whole.state_dict(), back.state_dict()
    for k in ("fitness", "species_hint", "proto_ids"):
        assert torch.equal(a[k], b[k])
    for k, v in a["archive"].items():
        if isinstance(v, dict):
            assert all(torch.equal(v[f], b["archive"][k][f]) for f in v)
        else:
            assert torch.equal(v, b["archive"][k])


def test_a_malformed_archive_in_a_checkpoint_is_refused():
    cfg = replace(SMALL, refound_after=2)
    ev = _run(cfg, 2)
    d = state_dict(ev.state, ev.cfg)
    d["archive"] = {**d["archive"], "died": torch.zeros(3, dtype=torch.long)}
    with pytest.raises(ValueError, match="re-founding archive"):
        load_state_dict(d, ev.ctx)
