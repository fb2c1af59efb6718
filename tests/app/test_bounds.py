"""Bounds on what a user can type, the same through the CLI and the API (issue 39, item 6 and
10): each out-of-bounds value is one line naming the option, and nothing is written."""

import json

import pytest
from replaykit import DESIGNS
from typer.testing import CliRunner

import swarmcode_torch as sc
from swarmcode_torch.app.analysis import replay_run, run_dynamics
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.files import RunError
from swarmcode_torch.app.runs import write_config
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.sim.runtime import MAX_THREADS, set_threads


def _run(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    write_config(run, SwarmCoDeConfig(scenario="two-niche", ticks=30))
    (run / "summary.json").write_text(
        json.dumps({"designs": DESIGNS, "best_fitness": 12.5, "best_generation": 4})
    )
    return run


@pytest.mark.parametrize(
    "kw, name",
    [
        ({"ticks": 0}, "ticks"),
        ({"ticks": 10**6}, "ticks"),
        ({"seed": -1}, "seed"),
        ({"fps": 0}, "fps"),
        ({"fps": float("nan")}, "fps"),
        ({"dpi": 10**6}, "dpi"),
        ({"every": 0}, "every"),
    ],
)
def test_replay_options_out_of_bounds_are_one_error_before_any_work(tmp_path, kw, name):
    run = _run(tmp_path)
    before = sorted(p.name for p in run.iterdir())
    with pytest.raises(RunError, match=rf"^{name} must be"):
        replay_run(run, **kw)
    assert sorted(p.name for p in run.iterdir()) == before


def test_replay_ticks_beyond_the_bound_is_one_line_in_the_cli(tmp_path):
    res = CliRunner().invoke(app, ["replay", str(_run(tmp_path)), "--ticks", "1000000"])
    assert res.exit_code != 0 and "ticks" in res.output and "Traceback" not in res.output


def test_threads_have_an_upper_bound(monkeypatch):
    import torch

    before = torch.get_num_threads()
    with pytest.raises(ValueError, match=f"threads must be <= {MAX_THREADS}"):
        set_threads(100_000)
    assert torch.get_num_threads() == before
    res = CliRunner().invoke(
        app, ["evolve", "--threads", "100000", "--generations", "1", "--logdir", "/nonexistent"]
    )
    assert res.exit_code != 0 and f"--threads must be <= {MAX_THREADS}" in res.output


@pytest.mark.parametrize("windows", [[(5, 1)], [(3, 3)], [(0, "a")], [(1, 2, 3)], [(True, 4)]])
def test_dynamics_windows_must_be_ordered_pairs(tmp_path, windows):
    with pytest.raises(RunError, match="windows"):
        run_dynamics(tmp_path, windows=windows)


def test_an_empty_logdir_or_preset_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(RunError, match="logdir"):
        sc.evolve(scenario="one-niche", generations=1, population=4, logdir="", progress=False)
    with pytest.raises(ValueError, match="preset"):
        sc.evolve(scenario="one-niche", generations=1, population=4, preset="", logdir=None)
    assert list(tmp_path.iterdir()) == []
    res = CliRunner().invoke(app, ["evolve", "--preset", "", "--logdir", str(tmp_path / "r")])
    assert res.exit_code != 0 and "preset" in res.output and "Traceback" not in res.output
    assert list(tmp_path.iterdir()) == []


def test_a_scenario_whose_packages_are_dicts_is_one_error(tmp_path):
    from dataclasses import replace

    from swarmcode_torch.sim.scenario import load_scenario

    s = load_scenario("one-niche")
    bad = replace(s, packages=[{"kind": "individual", "effector": "pincher", "count": 4}])
    with pytest.raises(TypeError, match="packages must be PackageClass objects, got dict"):
        sc.evolve(scenario=bad, generations=1, population=4, logdir=tmp_path, progress=False)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "history",
    [
        "abc",
        [1, 2, 3],
        [{"generation": "0", "population": {}, "team": {}}],
        [{"generation": 0, "population": {"a": 1}, "team": {}}],
        [{"generation": 0, "population": {"1": 2}}],
    ],
)
def test_composition_figure_of_garbage_is_one_error(history):
    with pytest.raises(ValueError, match="history"):
        sc.composition_figure(history)


def test_composition_figure_of_a_real_history_draws():
    fig = sc.composition_figure(
        [{"generation": g, "population": {"1": 3, "2": 1}, "team": {"1": 4}} for g in range(3)]
    )
    assert len(fig.axes) == 2
