"""`knockout_pairs`: two species of the best team that stand in for each other (each knock-out
alone costs nothing, the joint one a lot) are a substitute pair; the lower-ranked is demoted
from partner (`coevo.knockout.demote_substitutes`)."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import pytest
import torch
from evokit import assert_changes_and_repeats

from swarmcode_torch.coevo import knockout
from swarmcode_torch.coevo.admission import Admission
from swarmcode_torch.coevo.config import SwarmCoDeConfig

SMALL = replace(SwarmCoDeConfig(), scenario="two-niche", population=30, trials=2, ticks=40, seed=5)


def test_pair_rows_refill_both_species_from_the_rest_of_the_team():
    species = torch.tensor([7, 7, 8, 9, 9, 9])
    proto_ids = torch.tensor([7, 8, 9])
    team = torch.tensor([0, 1, 2, 3, 3, 4, -1, 0])
    out = torch.tensor([[True, True, False], [False, True, True], [True, True, True]])
    g = torch.Generator().manual_seed(0)
    for _ in range(20):
        teams, left = knockout.knocked_out(team, species, proto_ids, out, g)
        assert left.tolist() == [True, True, False]
        for r in range(2):
            gone = set(proto_ids[out[r]].tolist())
            hit = torch.tensor([t >= 0 and int(species[t]) in gone for t in team.tolist()])
            assert torch.equal(teams[r][~hit], team[~hit])
            kept = {int(t) for t, h in zip(team, hit) if t >= 0 and not h}
            assert {int(t) for t in teams[r][hit]} <= kept
        assert teams[2].tolist() == [-1] * 8  # nothing left to refill from


def test_single_rows_draw_as_knockout_teams_do():
    species = torch.tensor([7, 7, 8, 9, 9, 9])
    proto_ids = torch.tensor([7, 8, 9, 11])
    team = torch.tensor([0, 1, 2, 3, 3, 4, -1, 0])
    a, in_team = knockout.knockout_teams(team, species, proto_ids, torch.Generator().manual_seed(3))
    b, _ = knockout.knocked_out(
        team, species, proto_ids, torch.eye(4, dtype=torch.bool), torch.Generator().manual_seed(3)
    )
    assert torch.equal(a[1:], b) and in_team.tolist() == [True, True, True, False]


def test_a_pair_is_a_substitute_pair_only_when_each_alone_costs_little_and_both_a_lot():
    # m = 3: the team 100; alone: 0 costs 1, 1 costs 2, 2 costs 30; pairs (0,1) (0,2) (1,2)
    scores = torch.tensor([100.0, 99.0, 98.0, 70.0, 60.0, 50.0, 40.0])
    left = torch.tensor([True, True, True])
    assert knockout.substitute_pairs(scores, 3, left, 0.05).tolist() == [True, False, False]
    assert knockout.substitute_pairs(scores, 3, ~left, 0.05).tolist() == [False] * 3
    same = torch.tensor([100.0, 99.0, 98.0, 70.0, 97.0, 50.0, 40.0])  # the pair costs 3
    assert knockout.substitute_pairs(same, 3, left, 0.05).tolist() == [False] * 3


def _case(partner: list[bool], scores: list[float]):
    # species 4 (3 members), 5 (2), 6 (1); the best team holds all three
    species = torch.tensor([4, 4, 4, 5, 5, 6])
    sp = SimpleNamespace(species=species, proto_ids=torch.tensor([4, 5, 6]))
    res = SimpleNamespace(
        fitness=torch.tensor([9.0, 0, 0, 0, 0, 0]),
        swarms=SimpleNamespace(focal_team=torch.tensor([[0, 1, 3, 5, 0, 3]] * 6)),
    )
    n = 7
    adm = Admission(
        torch.tensor([True] * 4 + partner[:3]),
        torch.full((n,), 0.5),
        torch.ones(n, dtype=torch.long),
        torch.full((n,), 2, dtype=torch.long),
    )
    cfg = SimpleNamespace(knockout_pairs=0.05, best_team_tie=0.0)
    ctx = SimpleNamespace(cfg=cfg, scenario=None, eval_cfg=None)
    ctx.params = ctx.step_fn = ctx.score_fn = None
    fake = lambda teams, *a, **k: torch.tensor(scores)  # noqa: E731
    return adm, res, sp, ctx, fake


@pytest.mark.parametrize(
    "partner,scores,demoted",
    [
        # 4 and 5 stand in for each other: 5, the smaller, is demoted
        ([True, True, True], [100, 99, 99, 60, 40, 99, 99], 5),
        # 5 and 6 stand in for each other: 6, the smaller, is demoted
        ([True, True, True], [100, 60, 99, 99, 50, 50, 40], 6),
        # two pairs: the lowest-ranked loser of any (6) is demoted, one a generation
        ([True, True, True], [100, 99, 99, 99, 40, 99, 40], 6),
        # the loser is on probation already: nothing changes
        ([True, True, False], [100, 60, 99, 99, 50, 50, 40], None),
        # every knock-out alone costs the team: no pair
        ([True, True, True], [100, 60, 60, 60, 40, 40, 40], None),
    ],
)
def test_demote_the_lower_ranked_of_a_substitute_pair(monkeypatch, partner, scores, demoted):
    adm, res, sp, ctx, fake = _case(partner, scores)
    monkeypatch.setattr(knockout, "team_scores_on_shared_layouts", fake)
    out = knockout.demote_substitutes(adm, res, sp, None, None, ctx, torch.Generator())
    want = adm.partner.clone()
    if demoted is not None:
        want[demoted] = False
    assert torch.equal(out.partner, want)
    changed = (out.calm != adm.calm).nonzero().flatten().tolist()
    assert changed == ([] if demoted is None else [demoted])
    assert torch.equal(out.clash != adm.clash, out.calm != adm.calm)
    assert torch.equal(out.gated, adm.gated)


def test_off_or_open_admission_returns_the_admission_itself():
    adm, res, sp, ctx, _ = _case([True, True, True], [0.0] * 7)
    off = SimpleNamespace(cfg=SimpleNamespace(knockout_pairs=0.0))
    assert knockout.demote_substitutes(adm, res, sp, None, None, off, None) is adm
    assert knockout.demote_substitutes(None, res, sp, None, None, ctx, None) is None


def test_off_by_default_on_it_changes_the_run_and_repeats_itself():
    assert SwarmCoDeConfig().knockout_pairs == 0.0
    assert_changes_and_repeats(SMALL, 5, knockout_pairs=0.05)


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan")])
def test_margin_outside_the_unit_interval_is_refused(bad):
    with pytest.raises(ValueError, match="knockout_pairs"):
        replace(SMALL, knockout_pairs=bad).validate()
