"""The reused analysis tools of experiments/tools (compact runs, species tables, budget cost) on
tiny real runs: their files, tables and JSON hold what the run directories hold, read back
through the package's readers."""

import importlib.util
import json
import math
import statistics
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from swarmcode_torch.app.analysis import run_dynamics
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.runs import load_checkpoint, read_config, read_summary, read_teams

TOOLS = Path(__file__).resolve().parents[2] / "experiments" / "tools"
TINY = [
    "--scenario",
    "one-niche",
    "--population",
    "6",
    "--swarm-size",
    "4",
    "--trials",
    "1",
    "--ticks",
    "15",
    "--render-every",
    "0",
]
GENERATIONS = 4


def tool(name: str):
    spec = importlib.util.spec_from_file_location(f"experiment_tool_{name}", TOOLS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[tuple[int, int], Path]:
    """(budget, seed) -> run directory: two seeds at a budget every team is within, one seed at
    a budget every team is over."""
    out = {}
    for budget, seed in ((900, 0), (900, 1), (300, 0)):
        logdir = tmp_path_factory.mktemp(f"b{budget}s{seed}")
        r = CliRunner().invoke(
            app,
            [
                "evolve",
                *TINY,
                "--seed",
                str(seed),
                "--budget",
                str(budget),
                "--generations",
                str(GENERATIONS),
                "--logdir",
                str(logdir),
            ],
        )
        assert r.exit_code == 0, r.output
        (run,) = list(logdir.iterdir())
        out[budget, seed] = run
    return out


def test_compact_run_copies_the_run_and_writes_its_windows(runs, tmp_path):
    run = runs[900, 0]
    out = tmp_path / "compact"
    tool("compact_run").main([str(run), str(out)])
    assert sorted(p.name for p in out.iterdir()) == [
        "composition.png",
        "config.toml",
        "dynamics.json",
        "summary.json",
    ]
    for name in ("config.toml", "summary.json"):
        assert (out / name).read_bytes() == (run / name).read_bytes()
    assert (out / "composition.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    end = int(load_checkpoint(run)["generation"])
    assert end == GENERATIONS
    rows = json.loads((out / "dynamics.json").read_text())
    # windows of 100 from 0, then the last 50: here (0, 4) and (-46, 4), each holding the
    # run's 4 generations ("generations" is run_dynamics' count of the window's generations)
    assert [(r["from"], r["to"], r["generations"]) for r in rows] == [(0, 4, 4), (-46, 4, 4)]
    expected = run_dynamics(run, [(0, 4), (-46, 4)])
    for row, exp in zip(rows, expected):
        exp = json.loads(json.dumps(exp))  # as written: a NaN window value stays NaN
        assert row.keys() == exp.keys()
        for k, v in exp.items():
            assert row[k] == v or (isinstance(v, float) and math.isnan(v) and math.isnan(row[k])), k
    teams = read_teams(run)
    assert rows[0]["team_score"] == statistics.median(t["fitness"] for t in teams.values())


def test_compact_run_refuses_a_directory_that_is_not_a_run(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        tool("compact_run").main([str(tmp_path), str(tmp_path / "out")])
    assert str(e.value).startswith("error: ") and "\n" not in str(e.value)
    assert not (tmp_path / "out").exists()


def test_speciation_table_rows_and_cells_are_the_runs_dynamics(runs, tmp_path, capsys):
    st = tool("speciation_table")
    a, b = runs[900, 0], runs[900, 1]
    out = tmp_path / "table.json"
    st.main([f"tiny={a},{b}", "--last", "2", "--founding-from", "1", "--json", str(out)])
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == (
        "| group | runs | team sp | pop sp | niches | score | founded/gen | "
        "lasting/gen | lifetime | age |"
    )
    assert len(lines) == 3 and lines[2].startswith("| tiny | 2 | ")
    stored = json.loads(out.read_text())
    assert list(stored) == ["tiny"] and len(stored["tiny"]) == 2
    for row, run in zip(stored["tiny"], (a, b)):
        tail, long = run_dynamics(run, [(GENERATIONS - 2, GENERATIONS), (1, GENERATIONS)])
        assert row["run"] == str(run) and row["generations"] == GENERATIONS
        for k in ("team_species", "population_species", "niches", "team_score", "median_age"):
            assert row[k] == pytest.approx(tail[k], nan_ok=True), k
        for k in ("founded_per_generation", "founded_lasting_per_generation", "median_lifetime"):
            assert row[k] == pytest.approx(long[k], nan_ok=True), k
    cells = [c.strip() for c in lines[2].strip("|").split("|")]
    scores = [r["team_score"] for r in stored["tiny"]]
    mean, std = statistics.mean(scores), statistics.stdev(scores)
    assert cells[5] == f"{mean:.0f} ± {std:.0f} ({scores[0]:.0f}, {scores[1]:.0f})"
    # a group stored by --json is shown again, under another label, with the same cells
    st.main([f"@{out}:tiny=again"])
    again = capsys.readouterr().out.splitlines()[2]
    assert again == lines[2].replace("| tiny |", "| again |", 1)
    with pytest.raises(SystemExit, match="no group 'missing'"):
        st.main([f"@{out}:missing"])


def test_budget_cost_windows_and_table_iii_columns(runs, tmp_path, capsys):
    bc = tool("budget_cost")
    order = [(900, 0), (900, 1), (300, 0)]
    out = tmp_path / "cost.json"
    bc.main([str(runs[k]) for k in order] + ["--window", "2", "--json", str(out)])
    text = capsys.readouterr().out
    result = json.loads(out.read_text())
    assert [(r["budget"], r["seed"]) for r in result] == [(900.0, 0), (900.0, 1), (300.0, 0)]
    for res, key in zip(result, order):
        run = runs[key]
        cfg, teams, summary = read_config(run), read_teams(run), read_summary(run)
        assert (res["budget"], res["seed"], res["lam"]) == (cfg.budget, cfg.seed, cfg.lam)
        assert [w["generations"] for w in res["windows"]] == [[0, 1], [2, 3]]
        for w in res["windows"]:
            lo, hi = w["generations"]
            window = [teams[g] for g in range(lo, hi + 1)]
            over = [t for t in window if t["cost"] > cfg.budget]
            assert (w["over"]["n"], w["within"]["n"]) == (len(over), len(window) - len(over))
            assert w["over_share"] == round(len(over) / len(window), 2)
            assert w["cost"] == round(statistics.median(t["cost"] for t in window), 1)
            if w["within"]["n"]:  # no penalty within the budget
                assert w["within"]["score_before_penalty"] == w["within"]["score"]
            if w["over"]["n"]:  # the penalty lowers the score over it
                assert w["over"]["score_before_penalty"] > w["over"]["score"]
        assert res["best"] == {
            k: summary[k]
            for k in (
                "best_fitness",
                "team_cost",
                "deliveries",
                "deliveries_individual",
                "deliveries_collab",
                "num_species",
                "niches",
            )
        }
        tail = run_dynamics(run, [(GENERATIONS - 2, GENERATIONS)])[0]
        assert res["last"] == {
            k: tail[k] for k in ("team_species", "population_species", "niches", "team_score")
        }
        assert (res["last_cost"], res["last_over_share"]) == (
            res["windows"][-1]["cost"],
            res["windows"][-1]["over_share"],
        )
    # the tiny teams cost about $560: all within $900, all over $300
    assert {w["over_share"] for r in result[:2] for w in r["windows"]} == {0.0}
    assert {w["over_share"] for w in result[2]["windows"]} == {1.0}
    # the Table III rows, one per run, by budget; then the sweep over seeds (two at $900)
    table_iii, over_seeds = text.split("Over seeds")
    rows = [line for line in table_iii.splitlines() if line.startswith(("| 900 |", "| 300 |"))]
    assert [r.split("|")[1].strip() for r in rows] == ["300", "900", "900"]
    over_seeds = over_seeds.splitlines()
    row900 = next(line for line in over_seeds if line.startswith("| 900 | 0, 1 |"))
    fits = [r["best"]["best_fitness"] for r in result[:2]]
    mean, std = statistics.mean(fits), statistics.stdev(fits)
    assert f"| {mean:,.0f} ± {std:,.0f} |" in row900
    assert any(line.startswith("| 300 | 0 |") for line in over_seeds)
    assert not math.isnan(mean)


def test_budget_cost_refuses_a_run_without_a_budget_or_a_directory_that_is_not_a_run(tmp_path):
    bc = tool("budget_cost")
    with pytest.raises(SystemExit) as e:
        bc.main([str(tmp_path)])
    assert str(e.value).startswith("error: ") and "\n" not in str(e.value)
    logdir = tmp_path / "free"
    r = CliRunner().invoke(
        app, ["evolve", *TINY, "--seed", "0", "--generations", "1", "--logdir", str(logdir)]
    )
    assert r.exit_code == 0, r.output
    (run,) = list(logdir.iterdir())
    with pytest.raises(SystemExit, match="has no budget"):
        bc.main([str(run)])
