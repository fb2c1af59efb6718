"""Generated worlds (sim.worlds): the niche count of every world, checked by a search of this
file's own over the designs the hardware builds, with the simulator's lift rule; determinism;
the TOML file read back; refusals of worlds no team can solve; the train / test splits."""

from __future__ import annotations

import itertools
import json
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
import torch

from swarmcode_torch.sim.hardware import R_MAX, R_MIN, phenotype
from swarmcode_torch.sim.scenario import (
    EFFECTORS,
    ScenarioError,
    load_scenario,
    parse_scenario,
    scenario_from_dict,
)
from swarmcode_torch.sim.state import WorldParams, capabilities
from swarmcode_torch.sim.worlds import (
    FAMILIES,
    STUDY_SPECS,
    cheapest_robot,
    fewest_designs,
    generate_world,
    lift_shares,
    max_lift,
    split_seeds,
    study_world,
    study_worlds,
    world_toml,
)

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def train():
    return study_worlds("train")


@pytest.fixture(scope="module")
def test_split():
    return study_worlds("test")


# ------------------------------------------------------------------ an independent search
def all_designs(scenario):
    """Phenotypes of effector x radius x hardware: radii every 2.5 mm and at every band edge,
    every tier, torque operating points 0, 1/3, 2/3, 1, battery points 0 and 1."""
    radii = {R_MIN + i * (R_MAX - R_MIN) / 140 for i in range(141)}
    for c in scenario.packages:
        radii.update(x for x in c.radius_band if R_MIN <= x <= R_MAX)
    combos = list(
        itertools.product(
            sorted(EFFECTORS.values()),
            sorted(radii),
            range(3),
            range(3),
            range(3),
            (0.0, 1 / 3, 2 / 3, 1.0),
            (0.0, 1.0),
        )
    )
    t = torch.tensor(combos, dtype=torch.float32)
    return phenotype(
        t[:, 1], t[:, 2].long(), t[:, 3].long(), t[:, 4].long(), t[:, 5], t[:, 6], t[:, 0].long()
    )


def heaviest(scenario):
    return replace(
        scenario, packages=tuple(replace(c, mass=(c.mass[1], c.mass[1])) for c in scenario.packages)
    )


def check_niches(world):
    """The world needs exactly `world.niches` designs: each niche's exclusive class is lifted
    only by designs of that niche (effector, radius band), no design lifts the exclusive
    classes of two niches (so a team needs one design per niche), and one design per niche,
    each the one of its niche that lifts the most, together lift every class, collaborative
    ones at every grip, at their heaviest (so that many are enough)."""
    s, params = world.scenario, WorldParams.for_scenario(world.scenario)
    ph = all_designs(s)
    light = capabilities(ph, s, params)
    heavy = capabilities(ph, heaviest(s), params)
    niches = world.niche_designs
    assert len(niches) == world.niches
    team = []
    for k, x in enumerate(niches):
        mine = (ph.effector == EFFECTORS[x.effector]) & (ph.radius >= x.band[0] - 1e-6)
        mine &= ph.radius <= x.band[1] + 1e-6
        lifts = mine & heavy[:, x.exclusive]
        assert lifts.any(), f"niche {k}: none of its designs lifts its heaviest packages"
        if world.niches > 1:
            assert not (light[:, x.exclusive] & ~mine).any(), f"niche {k}: lifted from outside"
        for j, y in enumerate(niches):
            if j != k:
                both = light[:, x.exclusive] & light[:, y.exclusive]
                assert not both.any(), f"a design lifts the classes of niches {k} and {j}"
        best = int(torch.where(lifts, heavy.sum(dim=1), -1).argmax())
        team.append(best)
    held = heavy[team]
    effs = ph.effector[team]
    for i, c in enumerate(s.packages):
        for e in set(c.grips):
            assert (held[:, i] & (effs == e)).any(), f"the niches' designs do not lift class {i}"
    # the team's distinct capabilities (what a run reports as its niches)
    assert len({tuple(row.tolist()) for row in held}) == world.niches


def test_every_study_world_needs_the_niches_it_says(train, test_split):
    for w in train + test_split:
        check_niches(w)
        assert fewest_designs(w.scenario) == w.niches
        assert fewest_designs(w.scenario, heaviest=True) == w.niches


@pytest.mark.parametrize("family", FAMILIES)
def test_niche_count_of_every_family_and_band_mode(family):
    seed = 11
    niches = [1] if family == "single" else [2, 6] if family == "generalist" else [1, 6]
    for n in niches:
        w = generate_world(seed, niches=n, family=family, inversion=n % 2 == 1)
        check_niches(w)
        assert w.knobs["family"] == family and w.niches == n
    if family != "single":
        w = generate_world(seed, niches=4, family=family, bands="overlapping", mass=(2.0, 120.0))
        check_niches(w)
        # overlapping: some pair of bands of one effector does overlap
        bands = {}
        for x in w.niche_designs:
            bands.setdefault(x.effector, []).append(x.band)
        assert any(
            b1[0] <= a2[1] and a2[0] <= b1[1] for b in bands.values() for a2, b1 in zip(b, b[1:])
        )


def test_families_have_their_extra_classes():
    g = generate_world(5, niches=3, family="generalist")
    assert len(g.scenario.packages) == 4
    extra = g.scenario.packages[3]
    in_band = [x for x in g.niche_designs if x.band[0] >= extra.radius_band[0] - 1e-9]
    assert len([x for x in in_band if x.band[1] <= extra.radius_band[1] + 1e-9]) >= 2
    c = generate_world(5, niches=3, family="collab")
    assert [p.kind for p in c.scenario.packages] == ["individual"] * 3 + ["collab"]
    assert set(c.scenario.packages[3].grips) == {0, 1}
    s = generate_world(5, niches=1, family="single")
    assert len(s.scenario.packages) >= 2 and s.niches == 1
    assert fewest_designs(s.scenario, heaviest=True) == 1
    assert len({p.radius_band for p in s.scenario.packages}) > 1


def test_fewest_designs_gives_the_builtin_scenarios_niches():
    counts = {"one-niche": 1, "two-niche": 2, "four-niche": 4, "budget": 4}
    for name, n in counts.items():
        assert fewest_designs(load_scenario(name)) == n, name
    assert fewest_designs(load_scenario(str(ROOT / "examples/three-niche.toml"))) == 3
    # a class no robot lifts: no number of designs does
    s = load_scenario("one-niche")
    unsolvable = replace(s, packages=(replace(s.packages[0], mass=(500.0, 600.0)),))
    assert fewest_designs(unsolvable) is None


# ------------------------------------------------------------------ determinism and the file
def test_same_seed_and_knobs_give_the_same_bytes():
    kw = dict(niches=4, family="collab", inversion=True, budget=3000.0)
    a, b = world_toml(generate_world(42, **kw)), world_toml(generate_world(42, **kw))
    assert a == b
    assert world_toml(generate_world(43, **kw)) != a
    assert world_toml(generate_world(42, **{**kw, "niches": 3})) != a


@pytest.mark.subprocess
def test_the_bytes_are_the_same_in_another_process():
    code = (
        "import sys; from swarmcode_torch.sim.worlds import study_world, world_toml; "
        "sys.stdout.write(world_toml(study_world('test', 13)))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True
    ).stdout
    assert out == world_toml(study_world("test", 13))


def test_every_study_world_file_loads_back_equal(train, test_split, tmp_path):
    for w in train + test_split:
        text = world_toml(w)
        path = tmp_path / f"{w.scenario.name}.toml"
        path.write_text(text, encoding="utf-8")
        assert load_scenario(str(path)) == w.scenario
        assert parse_scenario(text.encode(), "x") == w.scenario
        assert scenario_from_dict(w.table) == w.scenario
        header = [ln for ln in text.splitlines() if ln.startswith("#")][:12]
        assert any(ln.startswith(f"# niches = {w.niches}: the fewest") for ln in header)
        assert any(f'"seed": {w.seed}' in ln for ln in header)
        assert "# reproduce: swarmcode-torch world --split" in text


def test_the_header_command_and_knobs_reproduce_the_world():
    w = generate_world(9, niches=2, family="generalist", mass=(3.5, 30.0), obstacles=2)
    text = world_toml(w)
    knobs = re.search(r"^# knobs: (.*)$", text, re.M).group(1)
    import json

    k = json.loads(knobs)
    seed = k.pop("seed")
    assert world_toml(generate_world(seed, **k)) == text
    assert "--mass 3.5,30" in text and "--obstacles 2" in text


# ------------------------------------------------------------------ refusals
def test_a_mass_beyond_any_robot_is_refused_at_once():
    top = max_lift()
    assert 100 < top < 200  # the built-in catalog's strongest robot
    with pytest.raises(ScenarioError, match=r"mass: \(200, 300\) kg: no robot .* lifts more than"):
        generate_world(1, mass=(200.0, 300.0))
    # the lift rule agrees: at 200 kg no design lifts anything
    s = load_scenario("one-niche")
    heavy = replace(s, packages=(replace(s.packages[0], mass=(200.0, 200.0)),))
    assert not capabilities(all_designs(heavy), heavy, WorldParams()).any()


def test_unsolvable_knobs_are_refused_with_the_reason():
    with pytest.raises(ScenarioError, match="no solvable world .* raise the mass range"):
        generate_world(1, niches=3, bands="overlapping")  # 2-24 kg cannot tell bands apart
    with pytest.raises(ScenarioError, match="niches: 4 niches need more effectors"):
        generate_world(1, niches=4, effectors=("pincher",))
    with pytest.raises(ScenarioError, match="family 'single' has 1 niche"):
        generate_world(1, niches=2, family="single")
    with pytest.raises(ScenarioError, match="'generalist' needs at least 2 niches"):
        generate_world(1, niches=1, family="generalist")
    with pytest.raises(ScenarioError, match="unknown effector 'gripper'"):
        generate_world(1, effectors=("gripper",))
    with pytest.raises(ScenarioError, match="niches: must be in"):
        generate_world(1, niches=7)
    with pytest.raises(ScenarioError, match="distance: .* from base_radius"):
        generate_world(1, distance=(1.0, 5.0))
    with pytest.raises(ScenarioError, match="num_robots: 2 robots cannot field"):
        generate_world(1, niches=3, num_robots=2)
    with pytest.raises(ScenarioError, match="packages: 3 packages for 4 package classes"):
        generate_world(1, niches=3, family="collab", packages=3)
    with pytest.raises(ScenarioError, match="seed"):
        generate_world(-1)


def test_min_lift_share_redraws_needle_worlds_and_is_written_in_the_header():
    # without the reach check: with it, no overlapping world of seed 0 or 1 passes both
    knobs = dict(niches=3, bands="overlapping", mass=(2.0, 120.0), min_reach=0.0)
    plain = generate_world(0, **knobs)
    assert min(lift_shares(plain.scenario)) < 0.01  # a needle without the knob
    w = generate_world(0, **knobs, min_lift_share=0.01)
    assert w.scenario != plain.scenario and min(lift_shares(w.scenario)) >= 0.01
    assert w.niches == 3 == fewest_designs(w.scenario, heaviest=True)
    text = world_toml(w)
    assert '"min_lift_share": 0.01' in text and "--min-lift-share 0.01" in text
    # a world drawn without it is written as before the knob existed
    assert "min_lift_share" not in world_toml(plain) and "lift-share" not in world_toml(plain)
    # the header's knobs draw it again
    k = json.loads(re.search(r"^# knobs: (.*)$", text, re.M).group(1))
    assert world_toml(generate_world(k.pop("seed"), **k)) == text
    # a check no draw passes: refused with the class and its share
    with pytest.raises(ScenarioError, match=r"no solvable world .* fewer than min_lift_share"):
        generate_world(1, **knobs, min_lift_share=0.2)
    with pytest.raises(ScenarioError, match=r"min_lift_share: must be in \[0, 0.5\]"):
        generate_world(1, min_lift_share=0.9)


def test_a_budget_that_cannot_field_the_niches_is_refused():
    with pytest.raises(ScenarioError, match=r"budget: \$1,000.00 cannot field 20 robots"):
        generate_world(1, budget=1000.0)
    free = generate_world(1)
    # the least a team with one robot per niche costs, from the closed form: its parts
    assert free.min_team_cost == pytest.approx(
        sum(free.cheapest) + 17 * cheapest_robot(0.0), rel=1e-6
    )
    w = generate_world(1, budget=free.min_team_cost - 1)  # redrawn until a team fits
    assert w.min_team_cost <= w.budget
    # above 20 of the cheapest robots and two species' overhead, below any team that lifts
    # two classes of 20-24 kg: every draw is refused
    with pytest.raises(ScenarioError, match="budget: .* cannot field 20 robots with one robot"):
        generate_world(1, niches=2, mass=(20.0, 24.0), species_overhead=500.0, budget=2495.0)


def test_cheapest_robot_is_no_dearer_than_any_design_that_lifts_the_load():
    s = load_scenario("one-niche")
    ph = all_designs(s)
    for load, band in ((0.0, (R_MIN, R_MAX)), (10.0, (0.15, 0.3)), (60.0, (0.3, 0.5))):
        cheapest = cheapest_robot(load, band, "pincher")
        probe = replace(s, packages=(replace(s.packages[0], mass=(load, load), radius_band=band),))
        ok = capabilities(ph, probe, WorldParams())[:, 0]
        assert ok.any()
        assert cheapest <= float(ph.cost[ok].min()) + 1e-3
        assert cheapest >= float(ph.cost[ok].min()) - 5.0  # and near the grid's cheapest
    assert cheapest_robot(0.0) == pytest.approx(74.55, abs=0.01)  # docs/MODEL.md: $75
    assert cheapest_robot(500.0) is None


# ------------------------------------------------------------------ the splits
def test_the_splits_are_fixed_and_disjoint(train, test_split):
    tr, te = split_seeds("train"), split_seeds("test")
    assert (tr.start, tr.stop, te.start, te.stop) == (1000, 2000, 5000, 6000)
    assert not set(tr) & set(te)
    with pytest.raises(ScenarioError, match="split"):
        split_seeds("validation")
    for split, worlds, seeds in (("train", train, tr), ("test", test_split, te)):
        assert len(worlds) == len(STUDY_SPECS) >= 12
        for k, w in enumerate(worlds):
            assert w.seed == seeds[k] and w.study == (split, k)
            assert w.scenario.name == f"study-{split}-{k:02d}"
        counts = [w.niches for w in worlds]
        assert sorted(set(counts)) == [1, 2, 3, 4, 5]
        assert all(counts.count(n) >= 2 for n in range(1, 6))
        assert {w.knobs["family"] for w in worlds} == set(FAMILIES)
        assert {w.knobs["bands"] for w in worlds} == {"disjoint", "overlapping"}
        assert {w.knobs["inversion"] for w in worlds} == {True, False}
    with pytest.raises(ScenarioError, match="index"):
        study_world("train", len(STUDY_SPECS))


def test_the_docs_table_lists_the_study_specs():
    page = (ROOT / "docs/WORLDS.md").read_text(encoding="utf-8")
    rows = re.findall(
        r"^\| (\d+) \| (\d) \| (\w+) \| ([\w, ]+) \| (\w+) \| ([\d.]+)-([\d.]+) \| (near|far) \|$",
        page,
        re.M,
    )
    assert len(rows) == len(STUDY_SPECS)
    for (k, n, fam, effs, bands, lo, hi, heavy), spec in zip(rows, STUDY_SPECS):
        assert int(n) == spec["niches"] and fam == spec["family"], k
        assert effs.split(", ") == list(spec.get("effectors", ("pincher", "suction")))
        assert bands == spec.get("bands", "disjoint")
        assert (float(lo), float(hi)) == tuple(spec.get("mass", (2.0, 24.0)))
        assert (heavy == "far") == spec.get("inversion", False)
