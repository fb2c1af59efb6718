"""`evolve` on CUDA (opt-in: `pytest -m gpu`; skipped without a GPU)."""

from dataclasses import replace

import pytest
import torch

from swarmcode_torch.evolve import Evolution, EvolveConfig

pytestmark = [pytest.mark.gpu,
              pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")]

TINY = EvolveConfig(scenario="budget", budget=4000.0, population=12, swarm_size=10, trials=2,
                    ticks=40, generations=3, seed=0, device="cuda")


@pytest.mark.parametrize("compiled", [False, True])
def test_evolve_runs_on_cuda(compiled):
    ev = Evolution(replace(TINY, compile=compiled))
    assert ev.ctx.device.type == "cuda" and ev.ctx.compiled == compiled
    while not ev.done:
        m = ev.step()
        assert m["team/cost"] > 0 and m["fitness/best"] > 0
    assert ev.state.genome.bt.device.type == "cuda"
    if compiled:
        assert ev.ctx.step_fn.error is None  # it really ran compiled


def test_cuda_checkpoint_resumes_on_cuda(tmp_path):
    from swarmcode_torch.runs import CheckpointReporter, resume, run, write_config

    cfg = replace(TINY, compile=False)
    write_config(tmp_path, cfg)
    run(Evolution(replace(cfg, generations=2)), tmp_path, [CheckpointReporter(tmp_path, 1)])
    ev = resume(tmp_path, generations=3)
    assert ev.state.generation == 2
    ev.step()
    assert ev.state.generation == 3
