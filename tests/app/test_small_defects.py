"""Small defects of issue 41 (item 8), each checked where a user sees it."""

import json
import re

from replaykit import design
from typer.testing import CliRunner

from swarmcode_torch.app.cli import app
from swarmcode_torch.app.runs import write_config
from swarmcode_torch.coevo.config import SwarmCoDeConfig

runner = CliRunner()


def test_print_config_says_how_to_use_the_settings_not_resume():
    r = runner.invoke(app, ["evolve", "--print-config", "--scenario", "one-niche"])
    assert r.exit_code == 0, r.output
    first = r.output.splitlines()[0]
    assert "--config FILE" in first and "--resume" not in first


def test_compile_help_says_the_cpu_runs_the_fused_tick():
    r = runner.invoke(app, ["evolve", "--help"], env={"COLUMNS": "200"})
    text = re.sub(r"\s+", " ", r.output)
    assert "fused C++ tick" in text and "on CPU for >= 50 generations]" not in text


def test_inspect_says_1_robot_not_1_robots(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    write_config(run, SwarmCoDeConfig(scenario="two-niche", ticks=30))
    designs = [
        design("pincher", 0.3, count=1, species=3),
        design("suction", 0.25, count=2, species=7),
    ]
    (run / "summary.json").write_text(
        json.dumps(
            {
                "designs": designs,
                **dict.fromkeys(
                    ("best_fitness", "team_cost", "deliveries", "deliveries_individual"), 1.0
                ),
                **dict.fromkeys(("deliveries_collab", "energy_used"), 0.0),
                "num_species": 2,
                "best_generation": 0,
                "budget": None,
            }
        )
    )
    r = runner.invoke(app, ["inspect", str(run)])
    assert "(1 robot," in r.output and "1 robots" not in r.output
    assert "(2 robots," in r.output
