"""The fitness weights as run settings: `--set` and API keywords, and runs saved before the
weights were keys (the weights themselves are tested in tests/coevo/test_fitness.py)."""

import torch

import swarmcode_torch as sc
from swarmcode_torch.app.runs import read_config
from swarmcode_torch.app.settings import parse_settings
from swarmcode_torch.coevo.config import FITNESS_KEYS
from swarmcode_torch.coevo.fitness import FitnessWeights

WEIGHT_KEYS = tuple(FITNESS_KEYS.values())  # the settings' names of the weights


def test_fitness_weights_by_set_and_by_api_keyword():
    assert parse_settings(["w_delivery=20", "inactive_factor=1"]) == {
        "w_delivery": 20.0,
        "inactive_factor": 1.0,
    }
    r = sc.evolve(
        scenario="one-niche",
        population=4,
        swarm_size=3,
        trials=1,
        ticks=6,
        generations=1,
        device="cpu",
        compile=False,
        logdir=None,
        w_delivery=20.0,
        fitness_floor=0.0,
    )
    assert r.evolution.ctx.eval_cfg.weights == FitnessWeights(W_delivery=20.0, floor=0.0)


def test_a_run_saved_before_the_weights_were_keys_resumes_with_the_same_values(tmp_path):
    tiny = dict(
        scenario="one-niche",
        population=4,
        swarm_size=3,
        trials=1,
        ticks=6,
        seed=3,
        device="cpu",
        compile=False,
        render_every=0,
    )
    first = sc.evolve(generations=2, logdir=tmp_path / "old", checkpoint_every=1, **tiny)
    run = first.run_dir
    text = (run / "config.toml").read_text()
    (run / "config.toml").write_text(
        "".join(
            line
            for line in text.splitlines(keepends=True)
            if line.split(" = ")[0] not in WEIGHT_KEYS
        )
    )
    assert "w_delivery" not in (run / "config.toml").read_text()
    ck = torch.load(run / "checkpoint.pt", weights_only=True)
    ck["config"] = {k: v for k, v in ck["config"].items() if k not in WEIGHT_KEYS}
    torch.save(ck, run / "checkpoint.pt")
    assert read_config(run).fitness_weights == FitnessWeights()
    assert sc.load(run).config.w_delivery == 100.0
    resumed = sc.resume(run, generations=3, render_every=0)
    assert resumed.config.fitness_weights == FitnessWeights()
    straight = sc.evolve(generations=3, logdir=tmp_path / "new", **tiny)
    assert (run / "teams.jsonl").read_text() == (straight.run_dir / "teams.jsonl").read_text()
    assert "w_delivery = 100.0" in (run / "config.toml").read_text()  # written back in full
