"""The SwarmCoDe fitness: raw task score, budget penalty, marginal-contribution gate and EMA.

Everything here is a pure, element-wise function of tensors (any batch shape).
"""

from __future__ import annotations

import torch
from torch import Tensor

from ..sim.tensors import cast
from .config import FitnessWeights

#: Keys `raw_fitness` reads from its metrics dict (all tensors of one common shape).
METRIC_KEYS = (
    "delivered_individual",
    "delivered_collab",
    "grips_delivered",
    "picked_individual",
    "picked_collab",
    "mean_final_energy",
    "proximity",
    "closeness",
)


def _weighted(w: float, x: Tensor) -> Tensor:
    """x * w (x itself for a weight of 1: the product would be x exactly)."""
    return x if w == 1.0 else x * w


def raw_fitness_terms(
    m: dict[str, Tensor], w: FitnessWeights = FitnessWeights()
) -> dict[str, Tensor]:
    """The terms of F_raw, each [...]: "delivery", "collab", "pickup", "energy", "proximity",
    "closeness" (weighted), "activity" (the inactive factor: 1, or w.inactive_factor for a team
    that picked nothing up); `raw_fitness` = max(w.floor, sum of the terms * activity)."""
    missing = [k for k in METRIC_KEYS if k not in m]
    if missing:
        raise KeyError(f"raw_fitness is missing metrics: {', '.join(missing)}")
    f = {k: cast(m[k], torch.float) for k in METRIC_KEYS}
    picked = f["picked_individual"] + f["picked_collab"]
    return {
        "delivery": f["delivered_individual"] * w.W_delivery,
        "collab": f["grips_delivered"] * w.W_delivery + f["delivered_collab"] * w.W_collab_bonus,
        "pickup": _weighted(w.W_pickup, picked),
        "energy": f["mean_final_energy"] * w.W_energy,
        "proximity": _weighted(w.W_proximity, f["proximity"]),
        "closeness": f["closeness"] * w.W_closeness,
        "activity": torch.where(picked <= 0, w.inactive_factor, 1.0),
    }


def raw_fitness(m: dict[str, Tensor], w: FitnessWeights = FitnessWeights()) -> Tensor:
    """dict of [...] metric tensors (see METRIC_KEYS) -> [...] float F_raw (>= w.floor)."""
    t = raw_fitness_terms(m, w)
    total = (
        t["delivery"] + t["collab"] + t["pickup"] + t["energy"] + t["proximity"] + t["closeness"]
    ) * t["activity"]
    return total.clamp(min=w.floor)


def budget_penalty(
    cost: Tensor, budget: float | Tensor | None, lam: float = 0.001, floor: float = 0.05
) -> Tensor:
    """[...] team cost -> [...] factor: max(floor, exp(-lam (cost - budget))) over budget,
    else 1."""
    cost = cast(cost, torch.float)
    if budget is None:
        return torch.ones_like(cost)
    if isinstance(budget, Tensor):
        budget = budget.to(dtype=cost.dtype, device=cost.device)
    over = cost - budget
    pen = torch.exp(-lam * over).clamp(min=floor)
    return torch.where(over > 0, pen, 1.0)


def gate(f_focal: Tensor, f_baseline: Tensor, p_marginal: float = 0.25) -> Tensor:
    """[...] focal / baseline team fitness -> [...]: f_focal if its marginal contribution
    f_focal - f_baseline is positive (it beats the baseline), else f_focal * p_marginal."""
    keep = beats_baseline(f_focal, f_baseline)
    return torch.where(keep, f_focal, f_focal * p_marginal)


def beats_baseline(f_focal: Tensor, f_baseline: Tensor) -> Tensor:
    """[...] bool: the marginal contribution f_focal - f_baseline is positive (the focal is not
    gated, `gate`)."""
    return f_focal - f_baseline > 0


def ema(prev: Tensor, new: Tensor, has_prev: Tensor, alpha: float = 0.6) -> Tensor:
    """[...] -> [...]: alpha*prev + (1-alpha)*new where has_prev, else new; alpha is the decay
    (weight of the OLD value)."""
    return torch.where(has_prev, alpha * prev + (1.0 - alpha) * new, new)


def team_cost(
    robot_cost: Tensor, robot_present: Tensor, species_count: Tensor, overhead: float
) -> Tensor:
    """[..., N] robot cost, [..., N] bool present, [...] species count -> [...] sum of present
    costs + overhead*count."""
    hw = torch.where(robot_present, robot_cost, 0.0).sum(-1)
    return hw + overhead * cast(species_count, hw.dtype)
