"""torch.compile and CUDA agree with the eager CPU tick (opt-in: ``pytest -m slow`` / ``-m gpu``)."""

from __future__ import annotations

import pytest
import torch
from worldkit import random_world

from swarmcode_torch.sim.rollout import rollout
from swarmcode_torch.sim.step import step

TICKS = 20
DISCRETE = ("t", "holding", "grip", "stuck", "p_status", "holder", "p_picked")


def _world(device="cpu"):
    """(layout, robots, tables, params): two random four-niche environments."""
    return random_world("four-niche", E=2, seed=0, device=device)[1:]


def _assert_close(want, got, pos_atol=1e-3):
    """Same discrete state; continuous state within tolerance (float reassociation only)."""
    for name in DISCRETE:
        a, b = getattr(want, name), getattr(got, name).to(getattr(want, name).device)
        assert torch.equal(a, b), f"{name}: {(a != b).sum().item()} entries differ"
    for name in ("pos", "waypoint", "p_pos"):
        torch.testing.assert_close(
            getattr(got, name).cpu(),
            getattr(want, name),
            atol=pos_atol,
            rtol=0,
            msg=lambda m: f"{name}: {m}",  # noqa: B023 - called inside this iteration
        )
    for name in ("vel", "p_vel"):
        torch.testing.assert_close(
            getattr(got, name).cpu(),
            getattr(want, name),
            atol=1e-3,
            rtol=0,
            msg=lambda m: f"{name}: {m}",  # noqa: B023 - called inside this iteration
        )
    torch.testing.assert_close(got.energy.cpu(), want.energy, atol=1e-2, rtol=1e-4)


@pytest.mark.slow
def test_compiled_step_matches_eager_on_cpu():
    # fullgraph: a graph break is an error. error_on_recompile: the step must compile exactly
    # once (its output state has the same shapes, dtypes and strides as reset()'s).
    # Positions may drift by float reassociation (fused kernels); over 20 ticks that is ~1e-6 m,
    # far from any threshold, so pickups, drops and deliveries must be identical.
    layout, rob, tables, params = _world()
    torch._dynamo.reset()
    compiled = torch.compile(step, dynamic=False, fullgraph=True)
    m_eager, want = rollout(layout, rob, tables, params, TICKS, return_state=True)
    with torch._dynamo.config.patch(error_on_recompile=True):
        m_comp, got = rollout(
            layout, rob, tables, params, TICKS, step_fn=compiled, return_state=True
        )
    _assert_close(want, got)
    for k in m_eager:
        torch.testing.assert_close(m_comp[k], m_eager[k], atol=1e-3, rtol=1e-4)


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_rollout_matches_cpu():
    # same inputs (drawn on the CPU, then moved); eager and compiled CUDA against eager CPU
    layout, rob, tables, params = _world()
    _, want = rollout(layout, rob, tables, params, TICKS, return_state=True)
    cuda = _world(device="cuda")
    _, got = rollout(*cuda, TICKS, return_state=True)
    _assert_close(want, got)
    torch._dynamo.reset()
    compiled = torch.compile(step, dynamic=False, fullgraph=True)
    with torch._dynamo.config.patch(error_on_recompile=True):
        _, got_c = rollout(*cuda, TICKS, step_fn=compiled, return_state=True)
    _assert_close(want, got_c)
