"""`evolve` on CUDA (opt-in: `pytest -m gpu`; skipped without a GPU)."""

from dataclasses import replace

import pytest
import torch

from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.evolve import Evolution

pytestmark = [
    pytest.mark.gpu,
    pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA"),
]

TINY = SwarmCoDeConfig(
    scenario="budget",
    budget=4000.0,
    population=12,
    swarm_size=10,
    trials=2,
    ticks=40,
    generations=3,
    seed=0,
    device="cuda",
)


@pytest.mark.parametrize(
    "compiled, graphs, mode",
    [
        (False, None, "eager"),
        (True, None, "compiled, CUDA graphs"),  # the default on CUDA
        (True, False, "compiled"),
    ],
)
def test_evolve_runs_on_cuda(compiled, graphs, mode):
    ev = Evolution(replace(TINY, compile=compiled, cuda_graphs=graphs))
    assert ev.ctx.device.type == "cuda" and ev.ctx.compiled == compiled
    assert ev.ctx.tick_mode == mode
    while not ev.done:
        m = ev.step()
        assert m.best_team.cost > 0 and m.best_fitness > 0
    assert ev.state.genome.bt.device.type == "cuda"
    if compiled:  # it really ran compiled
        compiled_step = ev.ctx.step_fn.step_fn if graphs is None else ev.ctx.step_fn
        assert compiled_step.error is None


def test_cuda_checkpoint_resumes_on_cuda(tmp_path):
    from swarmcode_torch.app.runs import CheckpointReporter, resume, run, write_config

    cfg = replace(TINY, compile=False)
    write_config(tmp_path, cfg)
    run(Evolution(replace(cfg, generations=2)), tmp_path, [CheckpointReporter(tmp_path, 1)])
    ev = resume(tmp_path, generations=3)
    assert ev.state.generation == 2
    ev.step()
    assert ev.state.generation == 3


def test_cuda_graph_ticks_match_compiled_rollout():
    """Replayed CUDA graphs give the compiled tick's results; same shapes reuse the capture,
    new shapes recapture."""
    from worldkit import random_world

    from swarmcode_torch.sim.rollout import rollout
    from swarmcode_torch.sim.runtime import CompiledStep, CudaGraphTicks

    compiled = CompiledStep()
    graphs = CudaGraphTicks(CompiledStep(), ticks_per_graph=10)
    captured = []
    for E, seed in ((6, 0), (6, 1), (4, 2)):  # reuse, then recapture
        _, layout, robots, tables, params = random_world(
            "four-niche", E=E, seed=seed, device="cuda"
        )
        ref = rollout(layout, robots, tables, params, 25, compiled)  # 2 replays + 5 ticks
        got = rollout(layout, robots, tables, params, 25, graphs)
        captured.append(graphs.graph)
        for k in ref:
            torch.testing.assert_close(got[k], ref[k], atol=1e-4, rtol=1e-4)
    assert captured[0] is captured[1] and captured[2] is not captured[1]
    assert compiled.error is None and graphs.step_fn.error is None


def test_evolve_with_cuda_graphs_replays_captured_ticks():
    from swarmcode_torch.sim.runtime import CudaGraphTicks

    ev = Evolution(replace(TINY, compile=True, cuda_graphs=True))
    assert isinstance(ev.ctx.step_fn, CudaGraphTicks)
    while not ev.done:
        m = ev.step()
        assert m.best_team.cost > 0 and m.best_fitness > 0
    assert ev.ctx.step_fn.graph is not None and ev.ctx.step_fn.step_fn.error is None


def test_build_tables_on_cuda_match_the_cpu():
    # on a GPU the walk runs without compaction (no device sync); the tables are the same
    from swarmcode_torch.sim import bt

    g = torch.Generator().manual_seed(0)
    ops = torch.cat(
        [
            bt.random_programs(60, 32, g),
            torch.stack([bt.template_tensor(n, 32) for n in bt.TEMPLATES]),
        ]
    )
    assert torch.equal(bt.build_tables(ops.cuda()).cpu(), bt.build_tables(ops))


@pytest.mark.parametrize("required", [True, False])
def test_cuda_graphs_when_compiling_fails(required):
    # evolve's default (graphs unset) falls back to eager ticks; an explicit choice is an error
    from worldkit import random_world

    from swarmcode_torch.sim.rollout import rollout
    from swarmcode_torch.sim.runtime import CompiledStep, CudaGraphTicks
    from swarmcode_torch.sim.step import step

    def broken(*args):
        raise RuntimeError("no compiler")

    failing = CompiledStep()
    failing.compiled = broken
    graphs = CudaGraphTicks(failing, required=required)
    _, layout, robots, tables, params = random_world("four-niche", E=4, seed=0, device="cuda")
    if required:
        with pytest.raises(RuntimeError, match="compiling failed"):
            rollout(layout, robots, tables, params, 20, graphs)
        return
    got = rollout(layout, robots, tables, params, 20, graphs)
    ref = rollout(layout, robots, tables, params, 20, step)
    assert graphs.disabled and graphs.graph is None
    for k in ref:
        torch.testing.assert_close(got[k], ref[k])
