"""Ask / tell (`coevo.ask_tell`): a run driven by ask, the built-in evaluation and tell is the
run `evolve` makes; a caller's own metrics drive it; misuse is one clear error."""

import pytest
import torch

import swarmcode_torch as sc
from swarmcode_torch.coevo.ask_tell import TELL_KEYS
from swarmcode_torch.coevo.config import SwarmCoDeConfig

TINY = SwarmCoDeConfig(
    scenario="two-niche",
    population=10,
    swarm_size=4,
    trials=2,
    ticks=12,
    generations=4,
    seed=3,
    device="cpu",
    compile=False,
)


def _same_state(a, b):
    for name, t in a.genome.state_dict().items():
        assert torch.equal(t, b.genome.state_dict()[name]), name
    assert torch.equal(a.fitness, b.fitness)
    assert torch.equal(a.has_fitness, b.has_fitness)
    assert torch.equal(a.species_hint, b.species_hint)
    assert torch.equal(a.proto_ids, b.proto_ids)
    assert torch.equal(a.rng_state, b.rng_state)
    assert a.history == b.history


def test_ask_tell_with_the_built_in_evaluation_is_the_run_evolve_makes():
    result = sc.evolve(TINY, logdir=None, progress=False)
    ev = sc.Evolution(TINY)
    told = []
    while not ev.done:
        asked = ev.ask()
        assert asked.generation == ev.state.generation
        P, S, T = TINY.population, TINY.swarm_size, TINY.trials
        assert asked.focal_team.shape == asked.baseline_team.shape == (P, S)
        assert asked.seeds.shape == (P * T,) and asked.environments == 2 * P * T
        assert ev.ask().seeds.tolist() == asked.seeds.tolist()  # asking again: the same teams
        metrics = asked.evaluate()
        assert set(TELL_KEYS) <= set(metrics)
        told.append(ev.tell(metrics))
    assert [r["fitness/best"] for r in result.history] == [r.best_fitness for r in told]
    assert [r["fitness/mean"] for r in result.history] == [r.mean_fitness for r in told]
    assert [r["species/count"] for r in result.history] == [r.num_species for r in told]
    assert result.species == [r.composition for r in told]
    _same_state(result.evolution.state, ev.state)


def test_told_metrics_are_what_the_generation_scores():
    """Metrics of the caller's drive the run: with every delivery and pick-up told as none, the
    generation's best team records none."""
    built_in, own = sc.Evolution(TINY), sc.Evolution(TINY)
    a = built_in.step()
    asked = own.ask()
    m = asked.evaluate()
    m = {
        k: v * 0 if k.startswith("delivered") or k.startswith("picked") else v for k, v in m.items()
    }
    b = own.tell(m)
    assert b.best_team.metrics["delivered_individual"] == 0
    assert a.generation == b.generation == 0
    assert own.state.generation == 1


def test_designs_of_a_team_name_each_slot():
    ev = sc.Evolution(TINY)
    asked = ev.ask()
    designs = asked.designs(asked.focal_team[0])
    assert len(designs) == TINY.swarm_size
    rows = asked.focal_team[0].tolist()
    for row, d in zip(rows, designs):
        if row < 0:
            assert d is None
        else:
            assert d["bt"] == asked.genome.bt[row].tolist()


def test_misuse_is_one_clear_error():
    ev = sc.Evolution(TINY)
    with pytest.raises(RuntimeError, match="call ask"):
        ev.tell({})
    asked = ev.ask()
    m = asked.evaluate()
    with pytest.raises(TypeError, match="dict"):
        ev.tell([1, 2])
    with pytest.raises(ValueError, match="missing: delivered_individual"):
        ev.tell({k: v for k, v in m.items() if k != "delivered_individual"})
    with pytest.raises(ValueError, match="shape"):
        ev.tell({**m, "energy_used": m["energy_used"][:3]})
    with pytest.raises(ValueError, match="NaN"):
        ev.tell({**m, "energy_used": m["energy_used"] * torch.nan})
    assert ev.state.generation == 0  # nothing told yet
    ev.tell(m)
    with pytest.raises(RuntimeError, match="call ask"):
        ev.tell(m)  # told already
