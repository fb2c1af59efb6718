"""Species dynamics and niches in a run's records and in `inspect` and `dynamics` (the
dynamics themselves are tested in tests/coevo/test_dynamics.py)."""

import json

import pytest
from typer.testing import CliRunner

from swarmcode_torch.app.analysis import design_capabilities
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.runs import load_checkpoint
from swarmcode_torch.coevo.dynamics import niche_count, replay
from swarmcode_torch.sim.scenario import load_scenario

FOUR = load_scenario("four-niche")


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    logdir = tmp_path_factory.mktemp("runs")
    r = CliRunner().invoke(
        app,
        [
            "evolve",
            "--scenario",
            "four-niche",
            "--population",
            "8",
            "--swarm-size",
            "5",
            "--trials",
            "1",
            "--ticks",
            "10",
            "--generations",
            "4",
            "--seed",
            "2",
            "--logdir",
            str(logdir),
            "--render-every",
            "0",
        ],
    )
    assert r.exit_code == 0, r.output
    (run,) = list(logdir.iterdir())
    return run


def test_a_run_records_niches_and_dynamics_everywhere(tiny_run):
    summary = json.loads((tiny_run / "summary.json").read_text())
    assert isinstance(summary["niches"], int) and 0 <= summary["niches"] <= 4
    recs = [json.loads(x) for x in (tiny_run / "teams.jsonl").read_text().splitlines()]
    for rec in recs:
        # the recorded niches are those of the recorded designs' genes
        caps = design_capabilities(
            [{k: v for k, v in d.items() if k != "capability"} for d in rec["designs"]], FOUR
        )
        assert caps == [d["capability"] for d in rec["designs"]]
        assert rec["niches"] == niche_count(caps)
    last = summary["last_generation"]
    for key in (
        "species/founded",
        "species/extinct",
        "species/median_age",
        "team/niches",
        "team/median_age",
    ):
        assert key in last
    # generation 0 founds every species of the population
    history = load_checkpoint(tiny_run)["history"]
    _, rows = replay(history)
    assert rows[0]["founded"] == len(history[0]["population"])


def test_inspect_prints_capabilities_and_dynamics_prints_windows(tiny_run):
    r = CliRunner().invoke(app, ["inspect", str(tiny_run)])
    assert r.exit_code == 0, r.output
    assert "lifts:" in r.output and "niches (distinct capabilities)" in r.output
    r = CliRunner().invoke(app, ["dynamics", str(tiny_run), "--window", "0:4", "--json"])
    assert r.exit_code == 0, r.output
    (st,) = json.loads(r.output)
    assert st["generations"] == 4 and st["from"] == 0 and st["to"] == 4
    r = CliRunner().invoke(app, ["dynamics", str(tiny_run)])
    assert r.exit_code == 0 and "founded" in r.output
    r = CliRunner().invoke(app, ["dynamics", str(tiny_run), "--window", "5:2"])
    assert r.exit_code == 2 and "--window" in r.output
