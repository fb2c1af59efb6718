"""Scenario registry, TOML loading and validation, hardware catalog and layouts."""

import math

import pytest
import torch

from swarmcode_torch.sim.hardware import R_MAX, R_MIN, default_catalog, phenotype
from swarmcode_torch.sim.layout import make_layouts, spawn_slots
from swarmcode_torch.sim.scenario import (
    ScenarioError,
    builtin_names,
    load_scenario,
    scenario_from_dict,
)

GOOD = {
    "name": "t",
    "arena": 20.0,
    "base_radius": 1.5,
    "num_robots": 4,
    "episode_ticks": 10,
    "obstacles": {"count": 2, "radius": [0.3, 0.5]},
    "packages": [
        {
            "kind": "individual",
            "effector": "pincher",
            "count": 3,
            "distance": [3.0, 6.0],
            "mass": [2.0, 4.0],
        },
        {
            "kind": "collab",
            "grips": ["pincher", "suction"],
            "count": 1,
            "distance": [4.0, 5.0],
            "mass": [10.0, 20.0],
        },
    ],
}


def test_registry_holds_the_papers_scenarios():
    assert set(builtin_names()) == {
        "one-niche",
        "two-niche",
        "four-niche",
        "budget",
        "swarm200",
        "swarm1000",
    }
    s = {n: load_scenario(n) for n in builtin_names()}
    for n in ("one-niche", "two-niche", "four-niche"):
        assert s[n].num_robots == 20 and s[n].num_packages == 16
    assert {p.grips for p in s["one-niche"].packages} == {(1,)}  # pinchers only
    assert {p.grips for p in s["two-niche"].packages} == {(0,), (1,)}
    assert s["budget"].species_overhead == 500.0
    assert any(p.kind == "collab" for p in s["budget"].packages)
    big = s["swarm200"]
    assert big.num_robots == 200
    assert sum(p.count for p in big.packages if p.kind == "individual") == 80
    assert sum(p.count for p in big.packages if p.kind == "collab") == 32
    assert not any(p.distance_weighting for p in big.packages)


def test_a_scenario_file_loads(tmp_path):
    f = tmp_path / "mine.toml"
    f.write_text(
        'name = "mine"\narena = 12\nbase_radius = 1\nnum_robots = 3\nepisode_ticks = 5\n'
        '[[packages]]\nkind = "individual"\neffector = "suction"\ncount = 2\n'
        "distance = [2, 4]\nmass = [1, 2]\n"
    )
    s = load_scenario(str(f))
    assert s.name == "mine" and s.arena == 12.0 and s.packages[0].grips == (0,)


@pytest.mark.parametrize(
    "patch,field",
    [
        ({"arena": -1.0}, "arena"),
        ({"num_robots": "x"}, "num_robots"),
        ({"base_radius": 50.0}, "base_radius"),
        ({"colour": "red"}, "colour"),
        ({"obstacles": {"count": -1}}, "obstacles.count"),
        ({"packages": []}, "packages"),
        (
            {"packages": [{"kind": "crate", "count": 1, "distance": [1, 2], "mass": [1, 2]}]},
            "packages[0].kind",
        ),
        (
            {
                "packages": [
                    {
                        "kind": "individual",
                        "effector": "magnet",
                        "count": 1,
                        "distance": [1, 2],
                        "mass": [1, 2],
                    }
                ]
            },
            "packages[0].effector",
        ),
        (
            {
                "packages": [
                    {
                        "kind": "individual",
                        "effector": "pincher",
                        "count": 1,
                        "distance": [5, 2],
                        "mass": [1, 2],
                    }
                ]
            },
            "packages[0].distance",
        ),
        (
            {
                "packages": [
                    {
                        "kind": "collab",
                        "grips": ["pincher"],
                        "count": 1,
                        "distance": [1, 2],
                        "mass": [1, 2],
                    }
                ]
            },
            "packages[0].grips",
        ),
        (
            {
                "packages": [
                    {"kind": "individual", "effector": "pincher", "count": 1, "distance": [1, 2]}
                ]
            },
            "packages[0].mass",
        ),
    ],
)
def test_malformed_scenarios_name_the_bad_field(patch, field):
    with pytest.raises(ScenarioError, match=field.replace("[", r"\[").replace("]", r"\]")):
        scenario_from_dict({**GOOD, **patch})


def test_unknown_scenario_lists_the_known_ones():
    with pytest.raises(ScenarioError, match="four-niche"):
        load_scenario("five-niche")


def test_premium_tiers_are_better_and_dearer():
    cat = default_catalog()
    assert cat.chassis_density[0] > cat.chassis_density[1] > cat.chassis_density[2]
    assert cat.chassis_strength[0] < cat.chassis_strength[1] < cat.chassis_strength[2]
    assert cat.motor_force[0] < cat.motor_force[1] < cat.motor_force[2]
    assert cat.motor_efficiency[0] < cat.motor_efficiency[1] < cat.motor_efficiency[2]
    assert cat.battery_density[0] < cat.battery_density[1] < cat.battery_density[2]
    one = lambda v: torch.tensor([v])  # noqa: E731
    costs = [
        phenotype(one(0.3), one(t), one(t), one(t), one(0.5), one(0.5), one(0)).cost.item()
        for t in range(3)
    ]
    assert costs[0] < costs[1] < costs[2]
    # the catalog spans the cost scale the paper's budgets imply (~$75-$350 a robot)
    lo = phenotype(one(R_MIN), one(0), one(0), one(0), one(0.0), one(0.0), one(0)).cost.item()
    hi = phenotype(one(R_MAX), one(2), one(2), one(2), one(1.0), one(1.0), one(1)).cost.item()
    assert 60 < lo < 100 and 300 < hi < 450


def test_layouts_respect_the_scenario():
    s = load_scenario("budget")
    L = make_layouts(s, 16, torch.Generator().manual_seed(0))
    base = torch.tensor([s.arena / 2, s.arena / 2])
    d = (L.p_pos - base).norm(dim=-1)
    lo = torch.tensor([c.distance[0] for c in s.packages for _ in range(c.count)])
    hi = torch.tensor([c.distance[1] for c in s.packages for _ in range(c.count)])
    assert ((d >= lo - 1e-4) & (d <= hi + 1e-4)).all()
    # distance weighting: heavier nearer the base within a class
    first = slice(0, s.packages[0].count)
    m, dd = L.p_mass[:, first].flatten(), d[:, first].flatten()
    assert torch.corrcoef(torch.stack([m, dd]))[0, 1] < -0.99
    # robots start without overlap
    sl = spawn_slots(20, 2 * R_MAX + 0.1)
    dist = torch.cdist(sl, sl) + torch.eye(20) * 100
    assert dist.min() >= 2 * R_MAX + 0.1 - 1e-4
    assert (L.g_effector[:, -4:] >= 0).all() and L.p_collab[:, -4:].all()
    # same generator seed, same layouts
    L2 = make_layouts(s, 16, torch.Generator().manual_seed(0))
    assert all(torch.equal(a, b) for a, b in zip(L, L2))
    assert not math.isnan(L.p_mass.sum().item())
