import math

import pytest
import torch

from swarmcode_torch.coevo.fitness import (FitnessWeights, budget_penalty, ema, gate, raw_fitness,

                                           team_cost)


def metrics(**kw):
    base = dict(delivered_individual=0.0, delivered_collab=0.0, grips_delivered=0.0,
                picked_individual=0.0, picked_collab=0.0, mean_final_energy=0.0, proximity=0.0,
                closeness=0.0)
    base.update(kw)
    return {k: torch.tensor(v, dtype=torch.float) for k, v in base.items()}


def test_weights_defaults():
    w = FitnessWeights()
    assert (w.W_delivery, w.W_collab_bonus, w.W_pickup, w.W_energy, w.W_proximity,
            w.W_closeness) == (100.0, 50.0, 1.0, 0.03, 1.0, 30.0)


def test_raw_fitness_hand_example():
    m = metrics(delivered_individual=2, delivered_collab=1, grips_delivered=2,
                picked_individual=3, picked_collab=1, mean_final_energy=50, proximity=2.5,
                closeness=0.5)
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
    assert torch.allclose(budget_penalty(cost, torch.tensor([0.0, 0.0, 0.0, 5000.0])),
                          torch.tensor([math.exp(-0.5), math.exp(-0.8), math.exp(-1.0), 1.0]))


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
