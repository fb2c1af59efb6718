"""Species dynamics (foundings, extinctions, ages, lifetimes) and niches (capabilities)."""

import math

import pytest
import torch

from swarmcode_torch.coevo.dynamics import Turnover, lifetimes, niche_count, replay, window_stats
from swarmcode_torch.coevo.population import from_designs, genome_phenotype
from swarmcode_torch.sim.hardware import phenotype
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.state import WorldParams, capabilities

FOUR = load_scenario("four-niche")


def design(effector, radius, tiers=3, torque=1.0, count=1, species=0):
    return {
        "species": species,
        "effector": effector,
        "radius": radius,
        "chassis_tier": tiers,
        "battery_tier": tiers,
        "motor_tier": tiers,
        "torque_point": torque,
        "battery_point": 1.0,
        "dominance": 0.5,
        "selectivity": 0.5,
        "count": count,
        "bt": [13] * 4,
    }


def design_capabilities(designs, scenario):
    """The package classes each design can lift, from its genes (what the application records
    as a design's `capability`)."""
    genome, _ = from_designs(designs)
    can = capabilities(
        genome_phenotype(genome, scenario.hardware), scenario, WorldParams.for_scenario(scenario)
    )
    return [[j for j, ok in enumerate(row) if ok] for row in can.tolist()]


def test_capabilities_of_hand_made_robots_in_four_niche():
    # classes: 0 heavy pincher, 1 heavy suction (r 0.32-0.5), 2 light pincher, 3 light suction
    # (r 0.15-0.3)
    designs = [
        design("pincher", 0.4),
        design("suction", 0.4),
        design("pincher", 0.2),
        design("suction", 0.2),
        design("pincher", 0.31),  # between the bands: lifts nothing
        design("pincher", 0.4, tiers=1, torque=0.0),
    ]  # too weak a motor for 16 kg
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
    assert capabilities(ph._replace(radius=t([0.2]), force=t([1e3])), FOUR, params).tolist() == [
        [False, False, True, False]
    ]


def test_niches_count_distinct_capabilities_not_species():
    caps = design_capabilities(
        [
            design("pincher", 0.2, species=1),
            design("pincher", 0.25, species=2),
            design("suction", 0.2, species=3),
        ],
        FOUR,
    )
    assert niche_count(caps) == 2  # two pincher species share one niche
    assert niche_count([[], []]) == 0
    budget = load_scenario("budget")
    # a collaborative package has a pincher and a suction grip: both effectors can take one
    caps = design_capabilities([design("pincher", 0.4), design("suction", 0.4)], budget)
    assert 4 in caps[0] and 4 in caps[1] and niche_count(caps) == 2


def test_founding_extinction_ages_and_lifetimes_on_a_scripted_sequence():
    # generation: species alive (ids are never reused)
    seq = [[0, 1, 2], [0, 1, 2, 3], [0, 2, 3, 4, 5], [0, 3, 5], [0, 3, 5, 6]]
    history = [
        {"generation": g, "population": {s: 1 for s in ids}, "team": {str(ids[0]): 1}}
        for g, ids in enumerate(seq)
    ]
    t, rows = replay(history)
    assert [(r["founded"], r["extinct"]) for r in rows] == [(3, 0), (1, 0), (2, 1), (0, 2), (1, 0)]
    assert [r["species"] for r in rows] == [3, 4, 5, 3, 4]
    # generation 2: species 0, 2 are 2 old, 3 is 1, 4 and 5 are 0 -> median 1
    assert rows[2]["median_age"] == 1
    assert rows[4]["team_median_age"] == 4  # species 0, founded at 0
    assert t.born == {0: 0, 1: 0, 2: 0, 3: 1, 4: 2, 5: 2, 6: 4}
    assert t.died == {1: 2, 2: 3, 4: 3}
    assert sorted(lifetimes(t, 0, 5)) == [1, 2, 3]  # 4 lived 1, 1 lived 2, 2 lived 3
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
    assert t.alive == frozenset({4, 5}) and u.alive == frozenset({5, 6})  # copy is independent
    assert u.ages(1, [5, 6]) == [1, 0]
