"""The quota floor of essential species (`essential_floor`): partners that beat their
baselines keep a few slots whatever their mean fitness, so a hard niche's holder is not starved."""

import torch
from genomekit import random_genomes

from swarmcode_torch.coevo.config import PRESETS, ReproductionParams, SwarmCoDeConfig
from swarmcode_torch.coevo.reproduction import floor_quotas, offspring_quotas, reproduce
from swarmcode_torch.coevo.speciation import distance


def test_floor_quotas_keep_the_total_and_give_each_chosen_species_its_floor():
    g = torch.Generator().manual_seed(0)
    for _ in range(200):
        k = int(torch.randint(1, 12, (1,), generator=g))
        p = int(torch.randint(k, 80, (1,), generator=g))
        fit = torch.rand(k, generator=g) ** 4
        q = offspring_quotas(fit, p, min_share=1.0)
        ess = torch.rand(k, generator=g) < 0.4
        pri = torch.rand(k, generator=g)
        floor = int(torch.randint(1, 5, (1,), generator=g))
        out = floor_quotas(q, ess, pri, floor)
        assert int(out.sum()) == p and bool((out >= 0).all())
        cap = p // (2 * floor)
        # the least-gated essential species, up to the cap, get at least the floor
        order = sorted(range(k), key=lambda i: float(pri[i]))
        chosen = [i for i in order if ess[i]][:cap]
        assert all(int(out[i]) >= floor for i in chosen)
        # a species that is not chosen never gains slots
        for i in range(k):
            if i not in chosen:
                assert int(out[i]) <= int(q[i])


def test_no_essential_species_or_a_floor_of_0_leaves_the_quotas():
    q = torch.tensor([10, 0, 5, 35])
    assert torch.equal(floor_quotas(q, torch.zeros(4, dtype=torch.bool), torch.zeros(4), 3), q)
    assert torch.equal(floor_quotas(q, torch.ones(4, dtype=torch.bool), torch.zeros(4), 0), q)


def test_a_starved_essential_species_keeps_its_floor_in_reproduce():
    """One individual of species 2 with a tenth of the others' fitness: min_share gives it no
    slot (it would go extinct); marked essential, it keeps `essential_floor` (3) slots."""
    gen = torch.Generator().manual_seed(1)
    genome = random_genomes(50, gen)
    species = torch.cat([torch.zeros(25), torch.ones(24), torch.full((1,), 2.0)]).long()
    fit = torch.cat([torch.full((49,), 100.0), torch.full((1,), 10.0)])
    proto_ids = torch.tensor([0, 1, 2])
    proto_index = torch.tensor([0, 25, 49])
    params = ReproductionParams(essential_floor=3)
    _, hint, _, _ = reproduce(genome, fit, species, proto_index, proto_ids, params, gen, distance)
    assert int((hint == 2).sum()) == 0
    _, hint, _, _ = reproduce(
        genome,
        fit,
        species,
        proto_index,
        proto_ids,
        params,
        gen,
        distance,
        essential=torch.tensor([False, False, True]),
        priority=torch.tensor([0.5, 0.5, 0.1]),
    )
    assert int((hint == 2).sum()) == 3 and hint.numel() == 50


def test_neither_the_default_nor_the_paper_preset_has_a_floor():
    """The floor was a candidate of the generalization study and was not adopted."""
    assert SwarmCoDeConfig().essential_floor == 0 and SwarmCoDeConfig().admission_basis == "members"
    assert PRESETS["paper"]["essential_floor"] == 0
