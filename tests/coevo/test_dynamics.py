"""Species dynamics (foundings, extinctions, ages, lifetimes) and niches (capabilities)."""

import json
import math

import pytest
import torch
from typer.testing import CliRunner

from swarmcode_torch.app.analysis import design_capabilities
from swarmcode_torch.app.cli import app
from swarmcode_torch.coevo.dynamics import Turnover, lifetimes, niche_count, replay, window_stats
from swarmcode_torch.sim.hardware import phenotype
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.state import WorldParams, capabilities

FOUR = load_scenario("four-niche")


def design(effector, radius, tiers=3, torque=1.0, count=1, species=0):
    return {"species": species, "effector": effector, "radius": radius, "chassis_tier": tiers,
            "battery_tier": tiers, "motor_tier": tiers, "torque_point": torque,
            "battery_point": 1.0, "dominance": 0.5, "selectivity": 0.5, "count": count,
            "bt": [13] * 4}


def test_capabilities_of_hand_made_robots_in_four_niche():
    # classes: 0 heavy pincher, 1 heavy suction (r 0.32-0.5), 2 light pincher, 3 light suction
    # (r 0.15-0.3)
    designs = [design("pincher", 0.4), design("suction", 0.4), design("pincher", 0.2),
               design("suction", 0.2),
               design("pincher", 0.31),                  # between the bands: lifts nothing
               design("pincher", 0.4, tiers=1, torque=0.0)]  # too weak a motor for 16 kg
    caps = design_capabilities(designs, FOUR)
    assert caps == [[0], [1], [2], [3], [], []]
    assert niche_count(caps) == 4
    # the weak robot fails on drive force alone: force < lift_force * (mass + lightest load)
    t = torch.tensor
    ph = phenotype(t([0.4]), t([0]), t([0]), t([0]), t([0.0]), t([1.0]), t([1]))
    params = WorldParams.for_scenario(FOUR)
    assert float(ph.payload) >= 16.0
    assert float(ph.force) < params.lift_force * (float(ph.mass) + 16.0)
    # a robot of the light band can still lift a light package of its effector class only
    assert capabilities(ph._replace(radius=t([0.2]), force=t([1e3])), FOUR, params).tolist() \
        == [[False, False, True, False]]


def test_niches_count_distinct_capabilities_not_species():
    caps = design_capabilities([design("pincher", 0.2, species=1), design("pincher", 0.25, species=2),
                                design("suction", 0.2, species=3)], FOUR)
    assert niche_count(caps) == 2                      # two pincher species share one niche
    assert niche_count([[], []]) == 0
    budget = load_scenario("budget")
    # a collaborative package has a pincher and a suction grip: both effectors can take one
    caps = design_capabilities([design("pincher", 0.4), design("suction", 0.4)], budget)
    assert 4 in caps[0] and 4 in caps[1] and niche_count(caps) == 2


def test_founding_extinction_ages_and_lifetimes_on_a_scripted_sequence():
    # generation: species alive (ids are never reused)
    seq = [[0, 1, 2], [0, 1, 2, 3], [0, 2, 3, 4, 5], [0, 3, 5], [0, 3, 5, 6]]
    history = [{"generation": g, "population": {s: 1 for s in ids}, "team": {str(ids[0]): 1}}
               for g, ids in enumerate(seq)]
    t, rows = replay(history)
    assert [(r["founded"], r["extinct"]) for r in rows] == [(3, 0), (1, 0), (2, 1), (0, 2), (1, 0)]
    assert [r["species"] for r in rows] == [3, 4, 5, 3, 4]
    # generation 2: species 0, 2 are 2 old, 3 is 1, 4 and 5 are 0 -> median 1
    assert rows[2]["median_age"] == 1
    assert rows[4]["team_median_age"] == 4              # species 0, founded at 0
    assert t.born == {0: 0, 1: 0, 2: 0, 3: 1, 4: 2, 5: 2, 6: 4}
    assert t.died == {1: 2, 2: 3, 4: 3}
    assert sorted(lifetimes(t, 0, 5)) == [1, 2, 3]      # 4 lived 1, 1 lived 2, 2 lived 3
    st = window_stats(rows, t, 2, 5, team_niches={2: 3, 3: 4, 4: 4})
    assert st["founded_per_generation"] == pytest.approx(3 / 3)
    # founded in 2..4: 4 (lived 1), 5 (alive 2..4: lasting), 6 (founded in the last generation:
    # not known yet) -> 1 lasting in 3 generations; over 0..4 every one but 4 and 6 lasted
    assert st["founded_lasting_per_generation"] == pytest.approx(1 / 3)
    assert window_stats(rows, t, 0, 5)["founded_lasting_per_generation"] == pytest.approx(5 / 5)
    assert st["extinct_per_generation"] == pytest.approx(3 / 3)
    assert (st["niches"], st["population_species"], st["median_lifetime"]) == (4, 4, 2)
    # a resumed run repeats generations: the last record of each counts once
    t2, rows2 = replay(history + history[3:])
    assert rows2 == rows
    assert math.isnan(window_stats(rows, t, 10, 20)["team_species"])


def test_turnover_advance_is_incremental_replay():
    t = Turnover()
    assert t.advance(0, [4, 5]) == (2, 0)
    u = t.copy()
    assert u.advance(1, [5, 6]) == (1, 1)
    assert t.alive == frozenset({4, 5}) and u.alive == frozenset({5, 6})   # copy is independent
    assert u.ages(1, [5, 6]) == [1, 0]


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    logdir = tmp_path_factory.mktemp("runs")
    r = CliRunner().invoke(app, ["evolve", "--scenario", "four-niche", "--population", "8",
                                 "--swarm-size", "5", "--trials", "1", "--ticks", "10",
                                 "--generations", "4", "--seed", "2", "--logdir", str(logdir),
                                 "--render-every", "0"])
    assert r.exit_code == 0, r.output
    (run,) = list(logdir.iterdir())
    return run


def test_a_run_records_niches_and_dynamics_everywhere(tiny_run):
    summary = json.loads((tiny_run / "summary.json").read_text())
    assert isinstance(summary["niches"], int) and 0 <= summary["niches"] <= 4
    recs = [json.loads(x) for x in (tiny_run / "teams.jsonl").read_text().splitlines()]
    for rec in recs:
        # the recorded niches are those of the recorded designs' genes
        caps = design_capabilities([{k: v for k, v in d.items() if k != "capability"}
                                    for d in rec["designs"]], FOUR)
        assert caps == [d["capability"] for d in rec["designs"]]
        assert rec["niches"] == niche_count(caps)
    last = summary["last_generation"]
    for key in ("species/founded", "species/extinct", "species/median_age", "team/niches",
                "team/median_age"):
        assert key in last
    # generation 0 founds every species of the population
    from swarmcode_torch.app.runs import load_checkpoint
    history = load_checkpoint(tiny_run)["history"]
    _, rows = replay(history)
    assert rows[0]["founded"] == len(history[0]["population"])


def test_inspect_prints_capabilities_and_dynamics_prints_windows(tiny_run):
    r = CliRunner().invoke(app, ["inspect", str(tiny_run)])
    assert r.exit_code == 0, r.output
    assert "lifts:" in r.output and "niches (distinct capabilities)" in r.output
    r = CliRunner().invoke(app, ["dynamics", str(tiny_run), "--window", "0:4", "--json"])
    assert r.exit_code == 0, r.output
    (st,) = json.loads(r.output)
    assert st["generations"] == 4 and st["from"] == 0 and st["to"] == 4
    r = CliRunner().invoke(app, ["dynamics", str(tiny_run)])
    assert r.exit_code == 0 and "founded" in r.output
    r = CliRunner().invoke(app, ["dynamics", str(tiny_run), "--window", "5:2"])
    assert r.exit_code == 2 and "--window" in r.output
