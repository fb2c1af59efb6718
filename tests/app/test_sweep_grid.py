"""Sweeps over any setting (`sweep --grid KEY=V1,V2`, `app.sweep_grid`): the runs of every grid
point, budget and seed, their progress, a resume after an interruption, the table with the
settings as columns; and `load_runs` (`app.load_runs`), one row per run."""

import csv
import re

import pytest
from typer.testing import CliRunner

import swarmcode_torch as sc
from swarmcode_torch.app import files
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.sweep_grid import SweepProgress, parse_grid

runner = CliRunner()
TINY = ["--scenario", "one-niche", "--generations", 2, "--population", 6, "--swarm-size", 4,
        "--trials", 1, "--ticks", 10, "--device", "cpu"]  # fmt: skip


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def _names(out):
    return sorted(p.name for p in out.iterdir() if p.is_dir())


def test_a_grid_over_a_setting_resumes_after_an_interrupt_and_tables_its_settings(
    tmp_path, monkeypatch
):
    out = tmp_path / "sweep"
    args = ["sweep", *TINY, "--grid", "delta=0.3,0.6", "--seeds", "0,1", "--budgets", "3000",
            "--out", out]  # fmt: skip
    names = [f"delta-{d}_budget-3000_seed-{s}" for d in ("0.3", "0.6") for s in (0, 1)]
    computed = []

    def interrupt(what):
        if what == "generation":
            computed.append(what)
            if len(computed) == 3:  # the second run's first generation
                raise KeyboardInterrupt

    monkeypatch.setattr(files, "interrupt_point", interrupt)
    r = invoke(*args)
    assert r.exit_code == 130, r.output
    assert "Sweep: run 1 of 4: " + names[
        0
    ] + " (8 generations left in the sweep, about ? left)" in (r.output)
    assert re.search(
        "Sweep: run 2 of 4: "
        + re.escape(names[1])
        + r" \(6 generations left in the sweep, about ~?[0-9dhms]+ left\)",
        r.output,
    )
    assert _names(out) == names[:2]
    monkeypatch.setattr(files, "interrupt_point", lambda what: None)
    r = invoke(*args)
    assert r.exit_code == 0, r.output
    assert f"{names[0]}: already done" in r.output
    # the interrupted run resumes from its checkpoint (generation 0: it was cut in its first)
    assert "Sweep: run 2 of 4: " + names[1] + " (6 generations left" in r.output
    assert "Sweep: run 4 of 4: " + names[3] in r.output
    assert _names(out) == sorted(names)
    rows = list(csv.DictReader((out / "table.csv").open()))
    assert [(r["delta"], r["budget"], r["seeds"]) for r in rows] == [
        ("0.3", "3000.0", "2"),
        ("0.6", "3000.0", "2"),
    ]
    table = (out / "table.md").read_text().splitlines()
    assert table[0].startswith("| delta | Budget | Best fitness")
    assert [line.split("|")[1].strip() for line in table[2:4]] == ["0.3", "0.6"]
    assert not (out / "budget.png").exists()  # a plot against budget is of budget sweeps
    r = invoke(*args)
    assert r.exit_code == 0 and r.output.count("already done") == 4

    runs = sc.load_runs(out / "*")
    assert [row["run"] for row in runs] == [str(out / n) for n in sorted(names)]
    assert sorted((row["delta"], row["seed"]) for row in runs) == [
        (0.3, 0), (0.3, 1), (0.6, 0), (0.6, 1)
    ]  # fmt: skip
    assert all(row["generations_done"] == 2 and row["stopped"] is None for row in runs)
    assert all(isinstance(row["best_fitness"], float) for row in runs)
    assert sc.load_runs(out) == runs  # a sweep directory stands for its runs
    pd = pytest.importorskip("pandas")
    df = runs.to_pandas()
    assert isinstance(df, pd.DataFrame) and len(df) == 4
    assert {"delta", "population", "seed", "best_fitness", "team_cost"} <= set(df.columns)
    assert df.groupby("delta").size().to_dict() == {0.3: 2, 0.6: 2}


def test_a_grid_of_two_keys_runs_every_combination_with_the_configs_budget(tmp_path):
    out = tmp_path / "s"
    r = invoke("sweep", "--scenario", "one-niche", "--generations", 1, "--swarm-size", 4,
               "--trials", 1, "--ticks", 8, "--device", "cpu", "--grid", "population=4,6",
               "--grid", "p_tag_flip=0.0,0.1", "--out", out)  # fmt: skip
    assert r.exit_code == 0, r.output
    budget = sc.SwarmCoDeConfig().budget
    b = "none" if budget is None else f"{budget:g}"
    assert _names(out) == sorted(
        f"population-{p}_p_tag_flip-{f}_budget-{b}_seed-0" for p in (4, 6) for f in ("0", "0.1")
    )
    rows = sc.load_runs(out)
    assert sorted((r["population"], r["p_tag_flip"]) for r in rows) == [
        (4, 0.0), (4, 0.1), (6, 0.0), (6, 0.1)
    ]  # fmt: skip
    header = (out / "table.md").read_text().splitlines()[0]
    assert header.startswith("| population | p_tag_flip | Budget")
    # --config: a run's settings to start from (its budget, population, p_tag_flip), a grid on top
    config = out / f"population-4_p_tag_flip-0.1_budget-{b}_seed-0" / "config.toml"
    r = invoke("sweep", "--config", config, "--grid", "delta=0.2,0.4", "--seeds", 7,
               "--out", tmp_path / "c")  # fmt: skip
    assert r.exit_code == 0, r.output
    rows = sc.load_runs(tmp_path / "c")
    assert [(r["delta"], r["seed"], r["population"], r["p_tag_flip"]) for r in rows] == [
        (0.2, 7, 4, 0.1), (0.4, 7, 4, 0.1)
    ]  # fmt: skip


@pytest.mark.parametrize(
    "grid, needle",
    [
        (["seed=1,2"], "--grid seed: use --seeds"),
        (["budget=1,2"], "--grid budget: use --budgets"),
        (["nope=1"], "--grid: unknown key 'nope'"),
        (["delta=a"], "--grid delta: expected values of type float"),
        (["delta=0.3,0.3"], "--grid delta lists 0.3 twice"),
        (["delta=0.3", "delta=0.4"], "--grid delta is given twice"),
        (["delta"], "--grid expects KEY=V1,V2"),
        (["population=4,6"], "--grid population: also given by --population"),
        (["delta=-1"], "delta"),
    ],
)
def test_bad_grids_are_one_line_errors_before_any_run(tmp_path, grid, needle):
    args = ["sweep", *TINY, "--out", tmp_path / "s"]
    for g in grid:
        args += ["--grid", g]
    r = invoke(*args)
    assert r.exit_code != 0 and "Traceback" not in r.output
    assert needle in r.output, r.output
    assert not (tmp_path / "s").exists() or not any((tmp_path / "s").iterdir())


def test_parse_grid_types_values_by_the_config():
    g = parse_grid(["population=4,6", "dominance=true,false", "quota_size_exponent=none,1.5"])
    assert g == {"population": [4, 6], "dominance": [True, False],
                 "quota_size_exponent": [None, 1.5]}  # fmt: skip


def test_sweep_progress_estimates_from_the_generations_run():
    now = [0.0]
    p = SweepProgress([3, 0, 5], clock=lambda: now[0])
    assert p.line(0, "a") == "Sweep: run 1 of 3: a (8 generations left in the sweep, about ? left)"
    now[0] = 30.0
    p.finished(0)
    p.finished(1)
    assert p.line(2, "c").endswith("(5 generations left in the sweep, about 50s left)")
    assert p.times() == "elapsed 30s, left ~50s"


def test_load_runs_of_nothing_and_of_bad_input():
    assert sc.load_runs("/nonexistent/*") == []
    with pytest.raises(ValueError, match="needs a pattern"):
        sc.load_runs()
    with pytest.raises(TypeError, match="pattern"):
        sc.load_runs(3)
