"""`best_team_floor`: a quota floor for the species of the generation's best team
(`coevo.shares`)."""

from __future__ import annotations

from dataclasses import replace

import torch
from evokit import evolve_seen

from swarmcode_torch.coevo import shares
from swarmcode_torch.coevo.config import SwarmCoDeConfig

SMALL = replace(SwarmCoDeConfig(), scenario="four-niche", population=30, trials=1, ticks=40, seed=5)


def test_best_team_species_are_those_of_the_fittest_individuals_focal_team():
    _, seen = evolve_seen(SMALL, 3)
    for e in seen:
        res, sp = e.evaluation, e.speciation
        b = int(res.fitness.argmax())
        rows = [r for r in res.swarms.focal_team[b].tolist() if r >= 0]
        want = {int(sp.species[r]) for r in rows}
        got = shares.best_team_species(res, sp)
        assert {int(i) for i in sp.proto_ids[got]} == want and want


def test_floor_gives_every_best_team_species_its_slots_and_keeps_the_total():
    cfg = replace(SMALL, best_team_floor=4)
    ev, seen = evolve_seen(cfg, 4)
    lifted = 0
    for e in seen:
        res, sp = e.evaluation, e.speciation
        best = shares.best_team_species(res, sp)
        plain = shares.plan(ev.cfg, ev.ctx.repro, sp, None, e.fitness)
        floored = shares.plan(ev.cfg, ev.ctx.repro, sp, None, e.fitness, best=best)
        assert int(floored.quota.sum()) == int(plain.quota.sum()) == cfg.population
        # at most population // (2 * floor) species get a floor (`floor_quotas`), the oldest
        cap = cfg.population // (2 * 4)
        assert int((floored.quota[best] >= 4).sum()) >= min(int(best.sum()), cap)
        lifted += int((plain.quota[best] < 4).sum())
    assert lifted > 0  # the floor changed some quota in these generations


def test_off_by_default_and_on_it_changes_the_run():
    assert SwarmCoDeConfig().best_team_floor == 0
    a, _ = evolve_seen(SMALL, 5)
    b, _ = evolve_seen(replace(SMALL, best_team_floor=4), 5)
    assert not torch.equal(a.state.species_hint, b.state.species_hint) or not torch.equal(
        a.state.fitness, b.state.fitness
    )
