"""`team_partners`: the species of the previous generation's best team are partners of every
focal, whatever the tags (`partners.team_partner_mask`, `choose_partners(always=...)`)."""

from dataclasses import replace
from types import SimpleNamespace

import torch
from evokit import assert_changes_and_repeats, evolve_seen
from test_partners import tags_at_distance

from swarmcode_torch.coevo import knockout
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.partners import choose_partners, team_partner_mask
from swarmcode_torch.coevo.population import Population, genome_phenotype

SMALL = replace(SwarmCoDeConfig(), scenario="four-niche", population=30, trials=2, ticks=40, seed=5)


def test_team_partner_mask_reads_the_last_best_team():
    ids = torch.tensor([3, 5, 8, 9])
    assert team_partner_mask([], ids) is None
    history = [{"team": {"3": 20}}, {"team": {"8": 12, "5": 7, "42": 1}}]
    # species 42 (extinct since) is not among the prototypes: nothing to mark
    assert team_partner_mask(history, ids).tolist() == [False, True, True, False]


def test_always_adds_partners_and_keeps_the_other_rules_and_the_draws():
    # focal tags 0; prototypes at distance 3, 12, 12, 0 bits; selectivity 0.25 takes the first only
    proto_tag = tags_at_distance([3, 12, 12, 0])
    proto_ids = torch.tensor([10, 11, 12, 13])
    elites = torch.tensor([[100, 110], [101, 111], [-1, -1], [103, -1]])
    tag = torch.zeros(3, 16, dtype=torch.bool)
    sel = torch.full((3,), 0.25)
    species = torch.tensor([13, 10, 11])
    always = torch.tensor([False, True, True, True])
    allowed = torch.tensor([True, True, True, False])

    def choose(*extra, **kw):
        args = (tag, sel, species, proto_ids, proto_tag, elites, torch.Generator().manual_seed(1))
        return choose_partners(*args, *extra, **kw)

    base, more, both = choose(), choose(always=always), choose(allowed, always)
    # species 11 joins every focal's partners but its own; 12 has no elite; 13 is never anyone's
    # partner but by tag (own species of focal 0), and `allowed` still rules it out
    assert (more[:, 1] >= 0).tolist() == [True, True, False]
    assert (more[:, 2] < 0).all()
    assert more[1, 3] >= 0 and more[0, 3] < 0
    assert (both[:, 3] < 0).all()
    # where a species is a partner in both, it is the same elite: the draws do not depend on it
    same = (base >= 0) & (more >= 0)
    assert same.any() and torch.equal(base[same], more[same])


def test_a_run_with_team_partners_puts_the_last_best_team_in_every_team():
    """Every focal's team holds a robot of each species of the previous best team that is still
    there (but its own), where the team has room for all its partners; and the setting changes
    a run, and repeats itself."""
    _, seen = evolve_seen(replace(SMALL, team_partners=True), 4)
    checked = 0
    for e in seen[1:]:
        sp, res = e.speciation, e.evaluation
        # room for every partner: a focal with more than S - 1 takes a random subset of them
        assert sp.proto_ids.numel() <= res.swarms.focal_team.shape[1]
        last = team_partner_mask(e.state.history, sp.proto_ids)
        for k in torch.nonzero(last).flatten().tolist():
            others = sp.species != sp.proto_ids[k]
            assert res.swarms.partner_in_team[others, k].all(), (e.generation, k)
            checked += int(others.sum())
    assert checked > 0
    assert_changes_and_repeats(SMALL, 4, team_partners=True)


def test_needed_ids_leave_out_a_species_another_stands_in_for():
    """`team_partners_margin`: two species of the same design in the best team each cost the team
    nothing when knocked out (each one's slots go to the other), so neither is a team partner."""
    ev, _ = evolve_seen(SMALL, 1)
    genome = ev.state.genome
    one = genome.index(slice(0, 1))
    twin = Population.cat([one, one, genome.index(slice(2, None))])  # row 1 a copy of row 0
    species = torch.full((genome.size,), 102)
    species[0], species[1] = 100, 101
    sp = SimpleNamespace(species=species, proto_ids=torch.tensor([100, 101, 102]))
    s = ev.ctx.eval_cfg.swarm_size
    team = torch.tensor([0, 1] * (s // 2) + [0] * (s % 2))
    res = SimpleNamespace(swarms=SimpleNamespace(focal_team=team[None]), fitness=torch.ones(1))
    cfg = replace(ev.cfg, team_partners=True, team_partners_margin=0.05)
    ctx = replace(ev.ctx, cfg=cfg)
    ph = genome_phenotype(twin, ctx.scenario.hardware)
    g = torch.Generator().manual_seed(0)
    assert knockout.needed_ids(res, sp, twin, ph, ctx, g) == []
    # with a margin below 0 every species in the team would count: the knock-outs ran
    credit = knockout.best_team_credit(res, sp, twin, ph, ctx, g, margin=-1.0)
    assert credit.tolist() == [True, True, False]


def test_a_run_with_a_margin_records_the_needed_species_and_partners_only_them():
    """Each generation records which of its best team's species are needed; every focal's team
    in the next holds each of those (but its own species'); the margin changes a run of team
    partners, and repeats itself."""
    on = replace(SMALL, team_partners=True)
    ev, seen = evolve_seen(replace(on, team_partners_margin=0.05), 4)
    kept = [(set(h["needed"]), {int(k) for k in h["team"]}) for h in ev.state.history]
    assert all(needed <= team for needed, team in kept)
    assert any(needed < team for needed, team in kept)  # some species of a best team left out
    checked = 0
    for e in seen[1:]:
        sp, res = e.speciation, e.evaluation
        last = team_partner_mask(e.state.history, sp.proto_ids)
        needed = torch.isin(sp.proto_ids, torch.tensor(e.state.history[-1]["needed"]))
        assert torch.equal(last, needed)
        for k in torch.nonzero(last).flatten().tolist():
            others = sp.species != sp.proto_ids[k]
            assert res.swarms.partner_in_team[others, k].all(), (e.generation, k)
            checked += int(others.sum())
    assert checked > 0
    assert_changes_and_repeats(on, 4, team_partners_margin=0.05)
