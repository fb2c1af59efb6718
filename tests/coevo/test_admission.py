"""Partner admission from the gate's statistics (`coevo.admission`, `partner_admission = "substitute"`)."""

import pytest
import torch

from swarmcode_torch.coevo.admission import Admission, AdmissionParams, update

P = AdmissionParams()


def _gated(species, gated_species):
    return torch.tensor([s in gated_species for s in species])


def _none(k):
    """No species has a nearest partner (`nearest_partner` of no allowed species)."""
    return torch.full((k,), -1)


def test_a_new_species_is_admitted_after_calm_generations_only():
    adm = Admission.empty().grow(2, partner=True).grow(3, partner=False)  # 0, 1 old; 2 new
    assert adm.partner.tolist() == [True, True, False]
    species = torch.tensor([0, 0, 1, 1, 2])
    ids = torch.tensor([0, 1, 2])
    for _gen in range(P.admit_generations):
        assert not adm.allowed(ids)[2]
        adm = update(adm, species, ids, _gated(species.tolist(), set()), _none(3))
    assert adm.allowed(ids).tolist() == [True, True, True] and adm.calm[2] == 0


def test_a_mostly_gated_species_stays_on_probation():
    adm = Admission.empty().grow(1, True).grow(2, False)
    species = torch.tensor([0, 0, 0, 1, 1])
    ids = torch.tensor([0, 1])
    for _ in range(20):
        adm = update(adm, species, ids, _gated(species.tolist(), {1}), _none(2))
    assert adm.partner.tolist() == [True, False]
    assert adm.gated[1] == 1.0 and adm.calm[1] == 0


def test_admission_state_round_trips_and_malformed_state_is_refused():
    adm = update(
        Admission.empty().grow(3, True),
        torch.tensor([0, 1, 2, 2]),
        torch.tensor([0, 1, 2]),
        torch.tensor([True, False, False, True]),
        _none(3),
    )
    back = Admission.from_state_dict(adm.state_dict())
    for k in ("partner", "gated", "calm", "clash"):
        assert torch.equal(getattr(adm, k), getattr(back, k))
    bad = adm.state_dict()
    bad["calm"] = bad["calm"][:2]
    with pytest.raises(ValueError, match="admission"):
        Admission.from_state_dict(bad)
    with pytest.raises(ValueError, match="admission"):
        Admission.from_state_dict({**adm.state_dict(), "gated": adm.gated.double()})


def test_substitute_rule_demotes_the_lower_ranked_of_a_species_and_its_nearest_partner():
    from swarmcode_torch.coevo.admission import SUBSTITUTE, nearest_partner

    # species 0 (4 members) and 2 (2 members) are near designs; 1 (3 members) is far from both
    dd = torch.tensor([[0.0, 0.9, 0.1], [0.9, 0.0, 0.8], [0.1, 0.8, 0.0]])
    allowed = torch.tensor([True, True, True])
    near = nearest_partner(dd, allowed)
    assert near.tolist() == [2, 2, 0]
    assert nearest_partner(dd, torch.tensor([True, False, False])).tolist() == [-1, 0, 0]
    adm = Admission.empty().grow(3, True)
    ids = torch.tensor([0, 1, 2])
    species = torch.tensor([0, 0, 0, 0, 1, 1, 1, 2, 2])
    # the large species 0 is the one gated (its robots the small 2 replaces at no loss): the
    # pair's lower-ranked member, 2, is demoted, not 0; 1, never gated, stays
    gated = torch.tensor([True, True, False, True, False, False, False, False, False])
    seen = []
    for _ in range(3):
        adm = update(adm, species, ids, gated, near, SUBSTITUTE)
        seen.append(adm.partner.tolist())
    assert seen == [[True] * 3, [True, True, False], [True, True, False]]


def test_a_gated_partner_whose_nearest_partner_is_another_design_is_not_a_substitute():
    """Demotion needs the nearest partner's design within δ (`near`): the species gated at or
    above one half is demoted when its nearest partner is near, never when it is far (a niche
    holder whose job does not pay yet, as early in a run)."""
    from swarmcode_torch.coevo.admission import SUBSTITUTE, nearest_partner

    dd = torch.tensor([[0.0, 0.9], [0.9, 0.0]])  # two far designs
    nearest = nearest_partner(dd, torch.tensor([True, True]))
    ids = torch.tensor([0, 1])
    species = torch.tensor([0, 0, 0, 1, 1])  # 0 the larger, 1 gated every time
    gated = torch.tensor([False, False, False, True, True])
    for near, want in (
        (torch.tensor([False, False]), [True, True]),
        (torch.tensor([True, True]), [True, False]),
    ):
        adm = Admission.empty().grow(2, True)
        for _ in range(SUBSTITUTE.clash_generations + 1):
            adm = update(adm, species, ids, gated, nearest, SUBSTITUTE, near=near)
        assert adm.partner.tolist() == want, near


def test_same_effector_pairs_a_far_nearest_partner_of_the_species_effector_only():
    """`demote_far_after`: past it, a far nearest partner counts as near when its robots have
    the species' effector, and the far pair of the test above is then a substitute pair."""
    from swarmcode_torch.coevo.admission import SUBSTITUTE, nearest_partner, same_effector

    effector = torch.tensor([0, 0, 1])
    nearest = torch.tensor([1, 0, -1])  # 0 and 1 each other's nearest; 2 has none
    assert same_effector(effector, nearest).tolist() == [True, True, False]
    assert same_effector(torch.tensor([0, 1]), torch.tensor([1, 0])).tolist() == [False, False]
    dd = torch.tensor([[0.0, 0.9], [0.9, 0.0]])
    nearest = nearest_partner(dd, torch.tensor([True, True]))
    near = same_effector(torch.tensor([1, 1]), nearest)
    species, ids = torch.tensor([0, 0, 0, 1, 1]), torch.tensor([0, 1])
    gated = torch.tensor([False, False, False, True, True])
    adm = Admission.empty().grow(2, True)
    for _ in range(SUBSTITUTE.clash_generations + 1):
        adm = update(adm, species, ids, gated, nearest, SUBSTITUTE, near=near)
    assert adm.partner.tolist() == [True, False]


def test_demote_far_after_is_off_by_default_and_changes_nothing_before_its_generation():
    """0 (the default) and a generation not reached yet give the default's run exactly."""
    from dataclasses import replace

    from swarmcode_torch.coevo.config import SwarmCoDeConfig
    from swarmcode_torch.coevo.evolve import Evolution

    cfg = SwarmCoDeConfig(
        scenario="two-niche",
        population=16,
        swarm_size=6,
        trials=1,
        ticks=30,
        generations=4,
        seed=2,
        device="cpu",
        compile=False,
    )
    assert cfg.demote_far_after == 0

    def run(c):
        ev = Evolution(c)
        return [ev.step().best_fitness for _ in range(4)], ev.state.genome.effector

    base = run(cfg)
    late = run(replace(cfg, demote_far_after=50))
    assert base[0] == late[0] and torch.equal(base[1], late[1])
    run(replace(cfg, demote_far_after=1))  # on from generation 1: runs


def test_a_checkpoint_with_a_damaged_admission_state_is_refused():
    from dataclasses import replace

    from swarmcode_torch.coevo.config import SwarmCoDeConfig
    from swarmcode_torch.coevo.evolve import Evolution

    cfg = SwarmCoDeConfig(
        scenario="one-niche",
        population=8,
        swarm_size=4,
        trials=1,
        ticks=10,
        generations=2,
        device="cpu",
        compile=False,
    )
    ev = Evolution(cfg)
    ev.step()
    d = ev.state_dict()
    assert d["admission"]["partner"].numel() == d["next_species_id"]
    assert Evolution.from_checkpoint(d, cfg).state.admission is not None
    short = {**d, "admission": {k: v[:-1] for k, v in d["admission"].items()}}
    with pytest.raises(ValueError, match="admission"):
        Evolution.from_checkpoint(short, cfg)
    assert Evolution.from_checkpoint({**d, "admission": None}, replace(cfg)).state.admission is None


def test_the_gated_share_is_that_of_the_elites_where_a_species_has_any():
    """A species of one elite that beats its baseline and three fresh offspring that do not: by
    its elites it is never gated (0.0), by all members 0.75; a species without elites is
    measured by its members."""
    adm = Admission.empty().grow(2, partner=False)
    species = torch.tensor([0, 0, 0, 0, 1, 1])
    gated = torch.tensor([False, True, True, True, True, False])
    elite = torch.tensor([True, False, False, False, False, False])
    nearest = torch.tensor([1, 0])
    ids = torch.tensor([0, 1])
    by_elites = update(adm, species, ids, gated, nearest, elite=elite)
    by_members = update(adm, species, ids, gated, nearest)
    assert by_elites.gated.tolist() == [0.0, 0.5]
    assert by_members.gated.tolist() == [0.75, 0.5]


@pytest.mark.parametrize("k", [1, 2, 6])
def test_a_substitute_is_demoted_after_exactly_clash_generations_above_one_half(k):
    """`demote_after` (`AdmissionParams.clash_generations`): a near partner gated every time is
    still a partner after k - 1 updates and on probation from the k-th, never before."""
    from dataclasses import replace

    from swarmcode_torch.coevo.admission import SUBSTITUTE

    params = replace(SUBSTITUTE, clash_generations=k)
    species, ids = torch.tensor([0, 0, 0, 1, 1]), torch.tensor([0, 1])
    gated = torch.tensor([False, False, False, True, True])
    nearest = torch.tensor([1, 0])
    adm = Admission.empty().grow(2, True)
    seen = []
    for _ in range(k + 2):
        adm = update(adm, species, ids, gated, nearest, params, near=torch.tensor([True, True]))
        seen.append(bool(adm.partner[1]))
    assert seen == [True] * (k - 1) + [False] * 3


def test_demote_after_is_the_run_s_clash_generations(monkeypatch):
    """The run setting reaches every admission update; its default, 2, is 0.7's rule."""
    from dataclasses import replace

    import swarmcode_torch.coevo.admission as A
    from swarmcode_torch.coevo.config import SwarmCoDeConfig
    from swarmcode_torch.coevo.evolve import Evolution

    seen = []
    orig = A.update

    def spy(adm, species, proto_ids, gated, nearest, params, **kw):
        seen.append(params.clash_generations)
        return orig(adm, species, proto_ids, gated, nearest, params, **kw)

    monkeypatch.setattr(A, "update", spy)
    cfg = SwarmCoDeConfig(
        scenario="two-niche", population=12, swarm_size=6, trials=1, ticks=20, seed=1,
        device="cpu", compile=False,
    )  # fmt: skip
    assert cfg.demote_after == A.SUBSTITUTE.clash_generations == 2
    for c, want in ((cfg, 2), (replace(cfg, demote_after=6), 6)):
        seen.clear()
        ev = Evolution(c)
        for _ in range(3):
            ev.step()
        assert seen == [want] * 3


@pytest.mark.parametrize("bad", [0, -1, 2.5])
def test_a_demote_after_below_one_or_not_a_whole_number_is_refused(bad):
    from swarmcode_torch.coevo.config import SettingError, SwarmCoDeConfig

    with pytest.raises(SettingError, match="demote_after"):
        SwarmCoDeConfig(demote_after=bad).validate()


def test_effector_first_makes_the_nearest_partner_one_of_the_same_effector_where_there_is_one():
    """`substitute_effector`: a species' nearest partner is of its effector where one is allowed,
    never within δ of another effector, and the distances are unchanged when off."""
    from swarmcode_torch.coevo.admission import effector_first, nearest_partner

    # 0 and 1 suction, 2 pincher; 0's nearest design is the pincher 2 (same size), then 1
    dd = torch.tensor([[0.0, 0.5, 0.35], [0.5, 0.0, 0.6], [0.35, 0.6, 0.0]])
    effector = torch.tensor([1, 1, 0])
    every = torch.tensor([True, True, True])
    assert torch.equal(effector_first(dd, effector, on=False), dd)
    assert nearest_partner(dd, every).tolist() == [2, 0, 0]
    first = effector_first(dd, effector)
    assert nearest_partner(first, every).tolist() == [1, 0, 0]  # 2 has no pincher partner
    assert (first[effector[:, None] != effector[None, :]] > 0.4).all()  # never within δ
    assert torch.equal(first[:2, :2], dd[:2, :2])
    assert nearest_partner(first, torch.tensor([True, False, True])).tolist() == [2, 0, 0]


def test_substitute_effector_is_off_by_default_and_changes_the_run_when_on():
    from dataclasses import replace

    from swarmcode_torch.coevo.config import SwarmCoDeConfig
    from swarmcode_torch.coevo.evolve import Evolution

    cfg = SwarmCoDeConfig(
        scenario="two-niche", population=16, swarm_size=6, trials=1, ticks=30, seed=3,
        device="cpu", compile=False,
    )  # fmt: skip
    assert cfg.substitute_effector is False

    def run(c):
        ev = Evolution(c)
        return [ev.step().best_fitness for _ in range(6)]

    assert run(cfg) == run(cfg)
    on = replace(cfg, substitute_effector=True)
    assert run(on) == run(on)
    assert run(on) != run(cfg)  # seed 3: a nearest partner of the other effector in generation <= 5
