"""`knockout_credit`: the best team's species credited by their knock-out (`coevo.knockout`)."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch
from evokit import assert_changes_and_repeats, evolve_seen

from swarmcode_torch.coevo import knockout, shares
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.population import genome_phenotype

SMALL = replace(SwarmCoDeConfig(), scenario="four-niche", population=30, trials=2, ticks=40, seed=5)


def test_knockout_teams_refill_only_the_species_slots_from_the_others():
    species = torch.tensor([7, 7, 8, 9, 9, 9])
    proto_ids = torch.tensor([7, 8, 9, 11])  # 11: a species with no robot in the team
    team = torch.tensor([0, 1, 2, 3, 3, 4, -1, 0])
    g = torch.Generator().manual_seed(0)
    for _ in range(20):
        teams, in_team = knockout.knockout_teams(team, species, proto_ids, g)
        assert teams.shape == (5, 8)
        assert torch.equal(teams[0], team)
        assert in_team.tolist() == [True, True, True, False]
        assert torch.equal(teams[4], team)  # not in the team: unchanged
        for k, sid in enumerate(proto_ids.tolist()):
            row = teams[1 + k]
            hit = (team >= 0) & (species[team.clamp(min=0)] == sid)
            assert torch.equal(row[~hit], team[~hit])  # other slots as they were
            others = {int(r) for r, h in zip(team, hit) if r >= 0 and not h}
            assert {int(r) for r in row[hit]} <= others  # re-filled from the others
            assert (row[hit] >= 0).all()


def test_knockout_of_the_only_species_empties_the_team():
    species = torch.tensor([3, 3])
    team = torch.tensor([0, 1, -1])
    teams, in_team = knockout.knockout_teams(
        team, species, torch.tensor([3]), torch.Generator().manual_seed(1)
    )
    assert in_team.tolist() == [True]
    assert teams[1].tolist() == [-1, -1, -1]


def test_species_count_of_each_team():
    species = torch.tensor([7, 7, 8, 9])
    teams = torch.tensor([[0, 1, 2, 3], [0, 0, 1, -1], [-1, -1, -1, -1], [3, 2, 2, 2]])
    got = knockout.team_species_count(teams, species, torch.tensor([7, 8, 9]))
    assert got.tolist() == [3, 1, 0, 2]


def test_credited_needs_a_loss_above_the_margin_and_a_place_in_the_team():
    scores = torch.tensor([100.0, 80.0, 96.0, 94.0, 10.0])
    in_team = torch.tensor([True, True, True, False])
    got = knockout.credited(scores, in_team, 0.05)
    # losses 20, 4, 6 (and 90 for a species not in the team): above 5 only for 0 and 2
    assert got.tolist() == [True, False, True, False]


def test_lift_raises_a_credited_species_to_the_top_mean_and_keeps_its_order():
    fit = torch.tensor([10.0, 30.0, 100.0, 60.0, 5.0, 7.0])
    species = torch.tensor([1, 1, 2, 2, 3, 3])
    proto_ids = torch.tensor([1, 2, 3])
    out = knockout.lift(fit, species, proto_ids, torch.tensor([True, False, False]))
    assert out[:2].mean() == pytest.approx(80.0)  # species 2's mean
    assert out[1] - out[0] == pytest.approx(20.0)  # order and gaps kept within the species
    assert torch.equal(out[2:], fit[2:])  # the others as they were
    top = knockout.lift(fit, species, proto_ids, torch.tensor([False, True, False]))
    assert torch.equal(top, fit)  # already the top mean: no change


def test_knockout_scores_share_environments_and_credit_moves_quotas_to_credited_species():
    ev, seen = evolve_seen(SMALL, 3)
    ctx = ev.ctx
    moved = 0
    for e in seen:
        res, sp = e.evaluation, e.speciation
        ph = genome_phenotype(e.state.genome, ctx.scenario.hardware)
        team = res.swarms.focal_team[res.fitness.argmax()]
        g = torch.Generator().manual_seed(e.generation)
        teams, in_team = knockout.knockout_teams(team, sp.species, sp.proto_ids, g)
        # the team twice more at the end: the same score, exactly, since every team runs on
        # the same environments
        scores = knockout.team_scores_on_shared_layouts(
            torch.cat([teams, teams[:1], teams[:1]]),
            e.state.genome,
            sp.species,
            sp.proto_ids,
            ctx.scenario,
            ctx.eval_cfg,
            g,
            ctx.params,
            ctx.step_fn,
            ctx.score_fn,
            ph,
        )
        assert scores[-2] == scores[0] and scores[-1] == scores[0]
        scores = scores[:-2]
        credit = knockout.credited(scores, in_team, 0.05)
        plain = shares.plan(ev.cfg, ctx.repro, sp, None, e.fitness)
        lifted = shares.plan(ev.cfg, ctx.repro, sp, None, e.fitness, credit=credit)
        assert int(lifted.quota.sum()) == int(plain.quota.sum()) == SMALL.population
        assert torch.equal(lifted.fit, plain.fit)  # selection within species reads fitness
        assert (lifted.quota[credit] >= plain.quota[credit]).all()
        moved += int((lifted.quota != plain.quota).any())
    assert moved > 0


def test_off_by_default_on_it_changes_the_run_and_repeats_itself():
    assert SwarmCoDeConfig().knockout_credit == 0.0
    assert_changes_and_repeats(SMALL, 4, knockout_credit=0.05)


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan")])
def test_margin_outside_the_unit_interval_is_refused(bad):
    with pytest.raises(ValueError, match="knockout_credit"):
        replace(SMALL, knockout_credit=bad).validate()


def test_knockout_floor_floors_the_credited_species_instead_of_lifting_them():
    ev, seen = evolve_seen(SMALL, 3)
    floored_any = 0
    for e in seen:
        sp = e.speciation
        k = sp.proto_ids.numel()
        credit = torch.zeros(k, dtype=torch.bool)
        credit[-1] = True  # the youngest species, credited
        plain = shares.plan(ev.cfg, ev.ctx.repro, sp, None, e.fitness)
        cfg = replace(ev.cfg, knockout_credit=0.05, knockout_floor=4)
        got = shares.plan(cfg, ev.ctx.repro, sp, None, e.fitness, credit=credit)
        best = shares.plan(
            replace(ev.cfg, best_team_floor=4), ev.ctx.repro, sp, None, e.fitness, best=credit
        )
        assert torch.equal(got.quota, best.quota)  # the best team's floor, for the credited
        assert int(got.quota[-1]) >= 4 and int(got.quota.sum()) == SMALL.population
        floored_any += int(plain.quota[-1]) < 4
    assert floored_any > 0
