import math

import pytest
import torch

from swarmcode_torch.coevo.fitness import (
    FitnessWeights,
    budget_penalty,
    ema,
    gate,
    raw_fitness,
    team_cost,
)


def metrics(**kw):
    base = dict(
        delivered_individual=0.0,
        delivered_collab=0.0,
        grips_delivered=0.0,
        picked_individual=0.0,
        picked_collab=0.0,
        mean_final_energy=0.0,
        proximity=0.0,
        closeness=0.0,
    )
    base.update(kw)
    return {k: torch.tensor(v, dtype=torch.float) for k, v in base.items()}


def test_weights_defaults():
    w = FitnessWeights()
    assert (
        w.W_delivery,
        w.W_collab_bonus,
        w.W_pickup,
        w.W_energy,
        w.W_proximity,
        w.W_closeness,
    ) == (100.0, 50.0, 1.0, 0.03, 1.0, 30.0)


def test_raw_fitness_hand_example():
    m = metrics(
        delivered_individual=2,
        delivered_collab=1,
        grips_delivered=2,
        picked_individual=3,
        picked_collab=1,
        mean_final_energy=50,
        proximity=2.5,
        closeness=0.5,
    )
    # 200 + (200 + 50) + 4 + 1.5 + 2.5 + 15
    assert raw_fitness(m).item() == pytest.approx(473.0)


def test_raw_fitness_inactivity_penalty_and_floor():
    inactive = metrics(mean_final_energy=50, closeness=0.2)
    assert raw_fitness(inactive).item() == pytest.approx((1.5 + 6.0) * 0.5)
    # only collaborative pickups count as activity too
    active = metrics(picked_collab=1, mean_final_energy=50, closeness=0.2)
    assert raw_fitness(active).item() == pytest.approx(1.0 + 1.5 + 6.0)
    assert raw_fitness(metrics()).item() == pytest.approx(0.1)
    small = metrics(mean_final_energy=4.0)  # 0.12 * 0.5 = 0.06 -> floor
    assert raw_fitness(small).item() == pytest.approx(0.1)


def test_raw_fitness_batched_and_weights():
    m = metrics(delivered_individual=[[1, 0], [0, 2]], picked_individual=[[1, 0], [0, 2]])
    out = raw_fitness(m, FitnessWeights(W_delivery=10.0))
    assert out.shape == (2, 2)
    assert torch.allclose(out, torch.tensor([[11.0, 0.1], [0.1, 22.0]]))


def test_raw_fitness_missing_key():
    m = metrics()
    del m["closeness"]
    with pytest.raises(KeyError):
        raw_fitness(m)


def test_budget_penalty_values():
    cost = torch.tensor([500.0, 800.0, 1000.0, 5000.0])
    out = budget_penalty(cost, 800.0)
    assert torch.allclose(out, torch.tensor([1.0, 1.0, math.exp(-0.2), 0.05]))
    assert torch.allclose(budget_penalty(cost, 800.0, lam=0.01)[2], torch.tensor(math.exp(-2.0)))
    assert torch.equal(budget_penalty(cost, None), torch.ones(4))
    assert torch.allclose(
        budget_penalty(cost, torch.tensor([0.0, 0.0, 0.0, 5000.0])),
        torch.tensor([math.exp(-0.5), math.exp(-0.8), math.exp(-1.0), 1.0]),
    )


def test_gate():
    f = torch.tensor([10.0, 10.0, 10.0])
    b = torch.tensor([5.0, 10.0, 20.0])
    assert torch.allclose(gate(f, b), torch.tensor([10.0, 2.5, 2.5]))
    assert torch.allclose(gate(f, b, p_marginal=0.5), torch.tensor([10.0, 5.0, 5.0]))


def test_ema():
    prev = torch.tensor([10.0, float("nan")])
    new = torch.tensor([0.0, 4.0])
    has = torch.tensor([True, False])
    assert torch.allclose(ema(prev, new, has), torch.tensor([6.0, 4.0]))
    assert torch.allclose(ema(prev, new, has, alpha=0.25), torch.tensor([2.5, 4.0]))


def test_team_cost():
    cost = torch.tensor([[1.0, 2.0, 4.0], [8.0, float("nan"), 1.0]])
    present = torch.tensor([[True, False, True], [True, False, False]])
    out = team_cost(cost, present, torch.tensor([2, 1]), overhead=10.0)
    assert torch.allclose(out, torch.tensor([25.0, 18.0]))


# ------------------------------------------------------------------ the weights as run settings
WEIGHT_KEYS = (
    "w_delivery",
    "w_collab_bonus",
    "w_pickup",
    "w_energy",
    "w_proximity",
    "w_closeness",
    "inactive_factor",
    "fitness_floor",
)


def test_fitness_weights_are_run_settings_with_one_default():
    from swarmcode_torch.coevo.config import FITNESS_KEYS, SwarmCoDeConfig

    assert sorted(FITNESS_KEYS.values()) == sorted(WEIGHT_KEYS)
    cfg = SwarmCoDeConfig()
    # the defaults are the run's, and FitnessWeights() is what a default run scores with
    assert cfg.fitness_weights == FitnessWeights() == cfg.evaluation(5, 10).weights
    assert (FitnessWeights().inactive_factor, FitnessWeights().floor) == (0.5, 0.1)
    custom = SwarmCoDeConfig(w_delivery=10, w_closeness=0.0, inactive_factor=1.0, fitness_floor=0.0)
    w = custom.evaluation(5, 10).weights
    assert (w.W_delivery, w.W_closeness, w.inactive_factor, w.floor) == (10.0, 0.0, 1.0, 0.0)
    assert isinstance(w.W_delivery, float)
    m = metrics(delivered_individual=1, picked_individual=1, closeness=1.0)
    assert raw_fitness(m, w).item() == pytest.approx(10.0 + 1.0)


@pytest.mark.parametrize(
    "key, value, needle",
    [
        ("w_delivery", -1.0, ">= 0"),
        ("w_energy", math.nan, ">= 0"),
        ("w_pickup", math.inf, ">= 0"),
        ("fitness_floor", -0.1, ">= 0"),
        ("inactive_factor", 1.5, "<= 1"),
        ("inactive_factor", -0.5, "in \\[0, 1\\]"),
        ("w_closeness", 1e20, "<= 1e\\+12"),
        ("w_collab_bonus", "50", "a number"),
        ("p_marginal", 2.0, "<= 1"),
        ("quota_size_exponent", math.nan, "in \\[0, 1\\]"),
        ("w_tag", -1.0, ">= 0"),
        ("gamma", 0.0, "> 0"),
        ("w_size", 1e9, "<= 1e\\+06"),
        ("partner_admission", "gate", "'open' or 'substitute', got 'gate'"),
        ("objective", "cost", "'fitness' or 'roi', got 'cost'"),
    ],
)
def test_fitness_and_quota_settings_are_validated(key, value, needle):
    from swarmcode_torch.coevo.config import SettingError, SwarmCoDeConfig

    with pytest.raises(SettingError, match=f"^{key} must .*{needle}") as e:
        SwarmCoDeConfig(**{key: value}).validate()
    assert e.value.key == key  # the application respells it (`settings.setting_message`)


def test_the_weights_change_the_scores():
    from dataclasses import replace

    from swarmcode_torch.coevo.config import SwarmCoDeConfig
    from swarmcode_torch.coevo.evolve import Evolution

    cfg = SwarmCoDeConfig(
        scenario="one-niche",
        population=6,
        swarm_size=3,
        trials=1,
        ticks=10,
        generations=1,
        seed=2,
        device="cpu",
        compile=False,
    )
    base = Evolution(cfg).step()
    floor = Evolution(replace(cfg, **dict.fromkeys(WEIGHT_KEYS[:6], 0.0), fitness_floor=7.0)).step()
    assert base.best_fitness != floor.best_fitness
    assert floor.best_team.fitness == pytest.approx(7.0)  # every term 0: the floor
