"""`equal_quotas_until`: equal offspring shares for every species early in a run (`coevo.shares.plan`)."""

import torch


def test_equal_quotas_give_every_species_the_same_share_until_their_generation():
    """`equal_quotas_until`: before it every species' offspring count is the same (up to the
    rounding of P / K), whatever its fitness; from it on, and by default, quotas follow fitness."""
    from dataclasses import replace

    from swarmcode_torch.coevo.config import SwarmCoDeConfig
    from swarmcode_torch.coevo.evolve import Evolution

    cfg = SwarmCoDeConfig(
        scenario="four-niche",
        population=40,
        swarm_size=6,
        trials=1,
        ticks=30,
        generations=4,
        seed=1,
        device="cpu",
        compile=False,
    )
    assert cfg.equal_quotas_until == 0

    def spreads(c):
        ev = Evolution(c)
        out = []

        def after(e):
            sp = e.speciation.species[e.parent]  # each offspring's parent's species
            counts = torch.bincount(torch.searchsorted(e.speciation.proto_ids, sp))
            counts = counts[counts > 0]
            out.append((int(counts.max() - counts.min()), int(e.speciation.proto_ids.numel())))

        ev.hooks.after_reproduction.append(after)
        for _ in range(3):
            ev.step()
        return out

    equal = spreads(replace(cfg, equal_quotas_until=2))
    assert all(spread <= 1 for spread, k in equal[:2] if k > 1), equal
    default = spreads(cfg)
    assert any(spread > 1 for spread, _ in default), default


def test_equal_quotas_leave_selection_within_a_species_to_fitness():
    """With equal shares the elites are still each species' fittest members (the shares read
    equal fitness, selection within a species the real one)."""
    from dataclasses import replace

    from swarmcode_torch.coevo import shares
    from swarmcode_torch.coevo.config import SwarmCoDeConfig
    from swarmcode_torch.coevo.evolve import Evolution

    cfg = SwarmCoDeConfig(
        scenario="four-niche", population=40, swarm_size=6, trials=1, ticks=30, seed=1
    )
    ev = Evolution(replace(cfg, equal_quotas_until=5))
    seen: list = []
    ev.hooks.after_evaluation.append(seen.append)
    for _ in range(3):
        ev.step()
    for e in seen:
        sp, fit = e.speciation, e.fitness
        equal = shares.plan(ev.cfg, ev.ctx.repro, sp, None, fit, equal=True)
        assert torch.equal(equal.fit, fit.float())  # what selection within a species reads
        counts = equal.quota[equal.quota > 0]
        assert int(counts.max() - counts.min()) <= 1
