"""An episode: reset, the tick loop, and its outcome (the per-environment metrics)."""

from __future__ import annotations

from collections.abc import Callable

import torch

from .layout import Layout
from .runtime import CudaGraphTicks
from .sense import sense
from .state import DELIVERED, Robots, State, TickInputs, WorldParams, compatible, random_keys, reset
from .step import step


# ---------------------------------------------------------------- outcome of an episode
def episode_metrics(state: State, layout: Layout, robots: Robots, params: WorldParams) -> dict:
    """Per-environment results ``[E]`` that the fitness needs, from the final state."""
    base = state.pos.new_tensor([params.arena / 2, params.arena / 2])
    present = robots.present.float()
    n_robots = present.sum(-1).clamp_min(1)
    collab = layout.p_collab & layout.p_present
    indiv = ~layout.p_collab & layout.p_present
    done = state.p_status == DELIVERED
    n_grips = (layout.g_effector >= 0).sum(-1)
    energy_pct = 100.0 * state.energy / robots.capacity.clamp_min(1e-9)
    mean_final = (energy_pct * present).sum(-1) / n_robots
    d_base = (state.pos - base).norm(dim=-1)
    prox = torch.where(state.holding >= 0, 10.0 / (1.0 + 0.1 * d_base), 0.0) * present
    d0 = (layout.p_pos - base).norm(dim=-1).clamp_min(1e-6)
    d1 = (state.p_pos - base).norm(dim=-1)
    progress = torch.where(done, 1.0, ((d0 - d1) / d0).clamp(0, 1))
    n_pk = layout.p_present.float().sum(-1).clamp_min(1)
    return {
        "delivered_individual": (done & indiv).sum(-1).float(),
        "delivered_collab": (done & collab).sum(-1).float(),
        "grips_delivered": torch.where(done & collab, n_grips, 0).sum(-1).float(),
        "picked_individual": (state.p_picked & indiv).sum(-1).float(),
        "picked_collab": (state.p_picked & collab).sum(-1).float(),
        "mean_final_energy": mean_final,
        "energy_used": 100.0 - mean_final,
        "proximity": prox.sum(-1) / n_robots,
        "closeness": (progress * layout.p_present).sum(-1) / n_pk,
    }


def rollout(
    layout: Layout,
    robots: Robots,
    tables: torch.Tensor,
    params: WorldParams,
    ticks: int,
    step_fn: Callable | None = None,
    return_state: bool = False,
    observe: Callable[[int, State], None] | None = None,
    observe_leaf: Callable[[int, torch.Tensor], None] | None = None,
):
    """Run `ticks` ticks of every environment; the per-environment metrics (and final state).

    `observe(t, state)`, if given, sees the state after reset (t = 0) and after every tick
    t = 1 .. ticks; a `CudaGraphTicks` step_fn then runs its ticks one by one.
    `observe_leaf(t, leaf)`, if given, sees the leaf statuses ``[E, N, 14]`` that the behavior
    trees read at tick t = 1 .. ticks (`sense` of the state before the tick, computed again
    outside the tick: the rollout's results do not change, and nothing is computed without it);
    `bt.trace` of a robot's program on them says which node acted.
    """
    compat = compatible(layout, robots, params)
    keys = random_keys(layout, robots.radius.shape[1])
    inputs = TickInputs(layout, robots, compat, keys, tables)
    state = reset(layout, robots, params)
    fn = step_fn or step
    if observe is not None or observe_leaf is not None:
        if observe is not None:
            observe(0, state)
        for t in range(1, ticks + 1):
            if observe_leaf is not None:
                observe_leaf(t, sense(state, layout, robots, compat, keys, params).leaf)
            state = fn(state, *inputs, params)
            if observe is not None:
                observe(t, state)
    elif isinstance(fn, CudaGraphTicks) or hasattr(fn, "run_ticks"):  # FusedTicks too
        state = fn.run_ticks(state, inputs, params, ticks)
    else:
        for _ in range(ticks):
            state = fn(state, *inputs, params)
    m = episode_metrics(state, layout, robots, params)
    return (m, state) if return_state else m
