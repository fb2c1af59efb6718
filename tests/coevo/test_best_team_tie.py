"""`best_team_tie`: of the focal teams within a fraction of the highest gated fitness, the best
team is one of the fewest species (`readout.best_index`)."""

from dataclasses import replace
from types import SimpleNamespace

import pytest
import torch
from evokit import assert_changes_and_repeats, evolve_seen

from swarmcode_torch.coevo import knockout
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.readout import best_index

SMALL = replace(SwarmCoDeConfig(), scenario="four-niche", population=30, trials=2, ticks=40, seed=5)


def _res(fitness, count):
    swarms = SimpleNamespace(focal_species_count=torch.tensor(count))
    return SimpleNamespace(fitness=torch.tensor(fitness), swarms=swarms)


def _reference(fitness: list[float], count: list[int], tie: float) -> int:
    """The rule as a loop: the highest fitness of the fewest species among those near the top
    (the first of equals); with `tie` 0, the first highest, whatever its species."""
    top = max(fitness)
    if tie <= 0:
        return fitness.index(top)
    near = [i for i, f in enumerate(fitness) if f >= top - tie * abs(top)]
    fewest = min(count[i] for i in near)
    return max((i for i in near if count[i] == fewest), key=lambda i: (fitness[i], -i))


@pytest.mark.parametrize(
    "fitness, count, tie, want",
    [
        ([10.0, 9.995, 9.999, 5.0], [3, 1, 2, 1], 0.0, 0),  # off: the highest
        ([10.0, 9.995, 9.999, 5.0], [3, 1, 2, 1], 1e-3, 1),  # the single species near the top
        ([10.0, 9.995, 9.999, 5.0], [3, 1, 2, 1], 1e-4, 2),  # 9.995 no longer near
        ([10.0, 9.995, 9.999, 5.0], [3, 2, 2, 1], 1e-3, 2),  # equal counts: the higher
        ([-10.0, -10.005, -11.0], [2, 1, 1], 1e-3, 1),  # a negative top: |top| sets the band
    ],
)
def test_best_index_takes_the_fewest_species_near_the_top(fitness, count, tie, want):
    assert int(best_index(_res(fitness, count), tie)) == want
    assert _reference(fitness, count, tie) == want


def test_best_index_matches_the_rule_on_random_draws():
    g = torch.Generator().manual_seed(0)
    for _ in range(200):
        n = int(torch.randint(1, 12, (1,), generator=g))
        # steps of 0.007 against bands of 0.01 and 0.1: no value on a band's edge
        fit = (100 + torch.randint(0, 5, (n,), generator=g) * 0.007).tolist()
        count = torch.randint(1, 4, (n,), generator=g).tolist()
        for tie in (0.0, 1e-4, 1e-3):
            assert int(best_index(_res(fit, count), tie)) == _reference(fit, count, tie)


def test_a_run_reports_the_team_the_rule_chooses_and_the_setting_repeats():
    # a wide band (20 %), so that the first generations, far from any tie, have teams in it
    ev, seen = evolve_seen(replace(SMALL, best_team_tie=0.2), 4)
    moved = 0
    for e, h in zip(seen, ev.state.history):
        res = e.evaluation
        b = _reference(res.fitness.tolist(), res.swarms.focal_species_count.tolist(), 0.2)
        team = res.swarms.focal_team[b]
        assert torch.equal(knockout.best_team(res, 0.2), team)
        ids = {str(int(s)) for s in e.speciation.species[team[team >= 0]].tolist()}
        assert set(h["team"]) == ids
        moved += b != int(res.fitness.argmax())
    assert moved > 0
    # off by default; on, with team partners (which read the best team), it changes a run
    assert SwarmCoDeConfig().best_team_tie == 0.0
    assert_changes_and_repeats(replace(SMALL, team_partners=True), 4, best_team_tie=0.5)


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan")])
def test_a_tie_outside_the_unit_interval_is_refused(bad):
    with pytest.raises(ValueError, match="best_team_tie"):
        replace(SMALL, best_team_tie=bad).validate()
