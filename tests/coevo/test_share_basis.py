"""`share_basis = "marginal"`: offspring shares follow each species' mean marginal contribution
(focal team's score less the baseline's, at least 0) instead of its mean fitness; selection
within species still reads fitness."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch
from evokit import assert_changes_and_repeats, evolve_seen

from swarmcode_torch.coevo import shares
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.reproduction import quotas

SMALL = replace(SwarmCoDeConfig(), scenario="four-niche", population=30, trials=2, ticks=40, seed=5)


def test_shares_follow_the_marginal_and_selection_still_reads_fitness():
    ev, seen = evolve_seen(SMALL, 3)
    moved = 0
    for e in seen:
        res, sp = e.evaluation, e.speciation
        marginal = (res.focal - res.baseline).clamp(min=0)
        got = shares.plan(ev.cfg, ev.ctx.repro, sp, None, e.fitness, marginal=marginal)
        # the reference: `reproduction.quotas` of the marginal itself, by species
        ref = quotas(marginal, sp.species, sp.proto_ids, ev.ctx.repro, present=True)
        assert torch.equal(got.quota, ref.quota)
        assert int(got.quota.sum()) == SMALL.population
        assert torch.equal(got.fit, e.fitness.float())  # selection within species: fitness
        plain = shares.plan(ev.cfg, ev.ctx.repro, sp, None, e.fitness)
        moved += int(not torch.equal(plain.quota, got.quota))
    assert moved > 0


def test_a_low_fitness_holder_with_the_largest_contribution_gets_the_largest_share():
    # species 0: high fitness, nothing a partner does not do (a substitute); species 1: its own
    # teams score low, but the team loses a lot without it
    species = torch.tensor([0, 0, 0, 1, 1, 1])
    ids = torch.tensor([0, 1])
    fitness = torch.tensor([900.0, 880.0, 860.0, 200.0, 180.0, 220.0])
    marginal = torch.tensor([0.0, 5.0, 0.0, 150.0, 120.0, 160.0])
    cfg = SwarmCoDeConfig()
    sp = type("Sp", (), {"species": species, "proto_ids": ids})()
    by_fit = shares.plan(cfg, cfg.reproduction, sp, None, fitness)
    by_marg = shares.plan(cfg, cfg.reproduction, sp, None, fitness, marginal=marginal)
    assert by_fit.quota.tolist()[0] > by_fit.quota.tolist()[1]
    assert by_marg.quota.tolist()[1] > by_marg.quota.tolist()[0]
    assert int(by_marg.quota.sum()) == 6


def test_the_sum_basis_pays_fitness_plus_marginal():
    species = torch.tensor([0, 0, 0, 1, 1, 1])
    fitness = torch.tensor([900.0, 880.0, 860.0, 200.0, 180.0, 220.0])
    res = type(
        "Res",
        (),
        {"focal": fitness, "baseline": fitness - torch.tensor([0, 5, 0, 700, 720, 690.0])},
    )()
    assert shares.basis("fitness", res, fitness) is None
    m = shares.basis("marginal", res, fitness)
    assert m.tolist() == [0.0, 5.0, 0.0, 700.0, 720.0, 690.0]
    both = shares.basis("fitness+marginal", res, fitness)
    assert torch.equal(both, fitness + m)
    cfg = SwarmCoDeConfig()
    sp = type("Sp", (), {"species": species, "proto_ids": torch.tensor([0, 1])})()
    got = shares.plan(cfg, cfg.reproduction, sp, None, fitness, marginal=both)
    ref = quotas(fitness + m, species, sp.proto_ids, cfg.reproduction, present=True)
    assert torch.equal(got.quota, ref.quota) and got.quota.tolist()[1] >= got.quota.tolist()[0]


@pytest.mark.parametrize("basis", ["marginal", "fitness+marginal", "marginal/slot"])
def test_off_by_default_on_it_changes_the_run_and_repeats_itself(basis):
    assert SwarmCoDeConfig().share_basis == "fitness"
    assert_changes_and_repeats(SMALL, 4, share_basis=basis)


def test_the_per_slot_basis_divides_by_the_slots_a_design_fills():
    ev, seen = evolve_seen(SMALL, 2)
    for e in seen:
        res = e.evaluation
        got = shares.basis("marginal/slot", res, e.fitness)
        marginal = shares.basis("marginal", res, e.fitness)
        slots = res.swarms.focal_slot.sum(1)
        assert int(slots.min()) >= 1  # slot 0 is always the focal's own
        for i in range(got.numel()):  # reference: one member at a time
            assert float(got[i]) == pytest.approx(float(marginal[i]) / int(slots[i]))
        assert bool((slots > 1).any())  # some designs fill more than one slot here
    # a holder filling 3 slots for 240 is paid above a generalist filling 17 for 800
    res = type(
        "Res",
        (),
        {
            "focal": torch.tensor([1000.0, 1000.0]),
            "baseline": torch.tensor([760.0, 200.0]),
            "swarms": type(
                "Sw", (), {"focal_slot": torch.arange(20) < torch.tensor([[3], [17]])}
            )(),
        },
    )()
    per = shares.basis("marginal/slot", res, torch.zeros(2))
    assert per.tolist() == pytest.approx([80.0, 800.0 / 17])


def test_an_unknown_basis_is_refused():
    with pytest.raises(ValueError, match="share_basis"):
        replace(SMALL, share_basis="novelty").validate()
