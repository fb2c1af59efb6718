"""The generator's reach check (sim.worlds.reach): a niche whose class no full swarm of its best
design brings home within an episode is redrawn (`min_reach`); the deliveries it reads agree
with the Python tick's, are exact counts and repeat."""

from __future__ import annotations

import json
import re

import pytest

from swarmcode_torch.sim import rollout as rollout_module
from swarmcode_torch.sim.scenario import ScenarioError
from swarmcode_torch.sim.step import step
from swarmcode_torch.sim.worlds import (
    REACH_LAYOUTS,
    REACH_SHARE,
    fetch_deliveries,
    generate_world,
    niche_reach,
    out_of_reach,
    study_world,
    world_toml,
)
from swarmcode_torch.sim.worlds import reach as reach_module


def test_fetch_deliveries_repeat_count_whole_packages_and_match_the_python_tick(monkeypatch):
    w = study_world("train", 8)  # niche 2's class is far from the base
    s, niche = w.scenario, w.niche_designs[1]
    radii = (0.4, 0.45)
    got = fetch_deliveries(s, niche.exclusive, niche.effector, radii)
    assert got == fetch_deliveries(s, niche.exclusive, niche.effector, radii)
    count = s.packages[niche.exclusive].count
    for x in got:  # a mean over REACH_LAYOUTS episodes of whole packages, at most the class's
        assert 0 <= x <= count and (x * REACH_LAYOUTS) == pytest.approx(round(x * REACH_LAYOUTS))
    # the same rollout with the Python reference tick gives the same counts
    seen = []

    def reference(*args, step_fn=None, **kw):
        seen.append(step_fn)
        return rollout_module.rollout(*args, step_fn=step, **kw)

    monkeypatch.setattr(reach_module, "rollout", reference)
    assert fetch_deliveries(s, niche.exclusive, niche.effector, radii) == got and seen


def test_the_reach_of_a_class_falls_with_the_episode_and_a_short_one_is_refused():
    w = generate_world(1, niches=2, min_reach=0.0)
    niche = w.niche_designs[0]
    full = niche_reach(w.scenario, niche)
    short = generate_world(1, niches=2, min_reach=0.0, episode_ticks=40)
    assert short.scenario.packages == w.scenario.packages  # the same draw, a shorter episode
    assert niche_reach(short.scenario, niche) < full
    assert (
        niche_reach(generate_world(1, niches=2, min_reach=0.0, episode_ticks=5).scenario, niche)
        == 0
    )
    # no draw of a 5-tick world brings anything home: refused, naming the niche and the check
    with pytest.raises(ScenarioError, match=r"no solvable world .* fewer than min_reach 50%"):
        generate_world(1, niches=2, episode_ticks=5)
    with pytest.raises(ScenarioError, match=r"min_reach: must be in \[0, 1\]"):
        generate_world(1, min_reach=-0.1)


def test_the_default_draws_worlds_whose_niches_are_within_reach():
    redrawn = 0
    for seed in range(4):
        plain = generate_world(seed, niches=4, min_reach=0.0)
        w = generate_world(seed, niches=4)
        assert w.knobs["min_reach"] == REACH_SHARE
        assert not out_of_reach(w.scenario, w.niche_designs)
        assert all(niche_reach(w.scenario, n) >= REACH_SHARE for n in w.niche_designs)
        if out_of_reach(plain.scenario, plain.niche_designs):
            redrawn += 1
            assert w.scenario != plain.scenario
        else:  # a world that passes at its first draw is the world drawn without the check
            assert w.table == plain.table
    assert redrawn >= 1  # seed 1: a suction niche far from the base
    # the header's knobs and command line name the check, and draw the world again
    text = world_toml(w)
    assert re.search(r'"min_reach": 0.5\b', text) and "--min-reach 0.5" in text
    assert re.search(r"--min-reach 0$", world_toml(plain), re.M)
    for world in (w, plain):
        text = world_toml(world)
        k = json.loads(re.search(r"^# knobs: (.*)$", text, re.M).group(1))
        assert world_toml(generate_world(k.pop("seed"), **k)) == text


def test_the_study_splits_are_drawn_as_before_the_check():
    w = study_world("train", 8)
    assert w.knobs["min_reach"] == 0.0 and "min_reach" not in world_toml(w)
    assert [i for i, _ in out_of_reach(w.scenario, w.niche_designs)] == [1]
