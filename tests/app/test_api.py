"""The Python API (`swarmcode_torch.evolve`, `resume`, `load`, `RunResult`), metrics.csv, the
TensorBoard hyperparameters, custom scenarios, the examples/ folder and `python -m`."""

import json
import math
import runpy
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import pytest
from typer.testing import CliRunner

import swarmcode_torch as sc
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.reporting import (
    HPARAM_METRICS,
    METRICS_FILE,
    SCALAR_TAGS,
    CsvReporter,
    read_metrics_csv,
)
from swarmcode_torch.app.runconfig import scenario_to_toml
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.sim.scenario import builtin_names, load_scenario

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
SETTINGS = dict(
    scenario="one-niche",
    population=4,
    swarm_size=3,
    trials=1,
    ticks=6,
    seed=3,
    budget=900.0,
    device="cpu",
    compile=False,
)
CLI_ARGS = [
    "--scenario",
    "one-niche",
    "--population",
    "4",
    "--swarm-size",
    "3",
    "--trials",
    "1",
    "--ticks",
    "6",
    "--seed",
    "3",
    "--budget",
    "900",
    "--device",
    "cpu",
    "--no-compile",
]


def only_dir(logdir: Path) -> Path:
    dirs = [d for d in Path(logdir).iterdir() if d.is_dir()]
    assert len(dirs) == 1, dirs
    return dirs[0]


def same(a, b) -> bool:
    """Equal, NaN equal to NaN."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def untimed(row: dict) -> dict:
    return {k: v for k, v in row.items() if not k.startswith("perf/")}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The same 2-generation run by the CLI and by the API."""
    base = tmp_path_factory.mktemp("runs")
    r = CliRunner().invoke(
        app,
        [
            "evolve",
            *CLI_ARGS,
            "--generations",
            "2",
            "--render-every",
            "0",
            "--logdir",
            str(base / "cli"),
        ],
    )
    assert r.exit_code == 0, r.output
    result = sc.evolve(generations=2, logdir=base / "api", render_every=0, **SETTINGS)
    return only_dir(base / "cli"), result


def test_api_run_directory_is_the_clis(runs):
    cli_dir, result = runs
    api_dir = result.run_dir
    assert api_dir.parent.name == "api" and api_dir.name.startswith("one-niche__b900__3__")
    for f in ("config.toml", "summary.json", "teams.jsonl", "checkpoint.pt", METRICS_FILE):
        assert (api_dir / f).is_file(), f
    assert list(api_dir.glob("events.out.tfevents.*"))

    def files(d):
        return {f.name for f in d.iterdir() if not f.name.startswith("events.out.tfevents.")}

    assert files(api_dir) - files(cli_dir) <= {METRICS_FILE}  # until the CLI writes it too
    assert files(cli_dir) <= files(api_dir)
    for f in ("config.toml", "scenario.toml", "hardware.toml"):
        assert (api_dir / f).read_bytes() == (cli_dir / f).read_bytes(), f
    assert (api_dir / "teams.jsonl").read_text().splitlines() == (
        cli_dir / "teams.jsonl"
    ).read_text().splitlines()

    def summary(d):
        s = json.loads((d / "summary.json").read_text())
        s["last_generation"] = untimed(s["last_generation"])
        return s

    assert summary(api_dir) == summary(cli_dir)
    if (cli_dir / METRICS_FILE).is_file():  # once the CLI writes metrics.csv too
        cli_rows, api_rows = (read_metrics_csv(d / METRICS_FILE)[0] for d in (cli_dir, api_dir))
        assert [untimed(r) for r in cli_rows] == [untimed(r) for r in api_rows]


def test_run_result_holds_history_species_and_best_team(runs):
    _, result = runs
    assert result.config.population == 4 and result.config.swarm_size == 3
    assert result.generations == 2 and result.scenario == load_scenario("one-niche")
    assert [h["generation"] for h in result.history] == [0, 1]
    for h in result.history:
        assert set(SCALAR_TAGS) <= set(h)
        assert all(isinstance(v, (int, float)) for v in h.values())
    assert [s["generation"] for s in result.species] == [0, 1]
    assert sum(result.species[-1]["population"].values()) == 4
    summary = json.loads((result.run_dir / "summary.json").read_text())
    best = result.best_team
    assert {"fitness", "cost", "species", "niches", "designs"} <= set(best)
    assert (best["fitness"], best["cost"], best["species"]) == (
        summary["best_fitness"],
        summary["team_cost"],
        summary["num_species"],
    )
    assert sum(d["count"] for d in best["designs"]) == 3
    assert "2/2 generations" in repr(result)


def test_metrics_csv_has_every_scalar_once_per_generation(runs):
    _, result = runs
    text = (result.run_dir / METRICS_FILE).read_text()
    header = text.splitlines()[0].split(",")
    assert header == ["generation", *SCALAR_TAGS]
    rows, _ = read_metrics_csv(result.run_dir / METRICS_FILE)
    assert len(rows) == 2
    for row, h in zip(rows, result.history):
        assert all(same(row[k], float(h[k]) if isinstance(row[k], float) else h[k]) for k in h)
    assert rows[0]["team/budget"] == 900.0


def test_tensorboard_gets_the_runs_hyperparameters(runs):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
    from tensorboard.plugins.hparams.plugin_data_pb2 import HParamsPluginData

    _, result = runs
    acc = EventAccumulator(str(result.run_dir))
    acc.Reload()
    content = acc.PluginTagToContent("hparams")
    assert {"_hparams_/experiment", "_hparams_/session_start_info"} <= set(content)
    start = HParamsPluginData.FromString(content["_hparams_/session_start_info"])
    hp = start.session_start_info.hparams
    assert hp["population"].number_value == 4 and hp["budget"].number_value == 900
    assert hp["scenario"].string_value == "one-niche" and hp["device"].string_value == "cpu"
    exp = HParamsPluginData.FromString(content["_hparams_/experiment"]).experiment
    assert {m.name.tag for m in exp.metric_infos} == set(HPARAM_METRICS)
    best = result.best_team
    assert acc.Scalars("best/fitness")[-1].value == pytest.approx(best["fitness"])
    assert acc.Scalars("best/species")[-1].value == best["species"]
    assert acc.Scalars("best/niches")[-1].value == best["niches"]


def test_in_memory_run_writes_nothing_and_matches_the_files(runs, tmp_path, monkeypatch):
    _, on_disk = runs
    monkeypatch.chdir(tmp_path)
    seen = []
    result = sc.evolve(
        sc.SwarmCoDeConfig(**SETTINGS, generations=2),
        logdir=None,
        callback=lambda r: seen.append(r.generation),
    )
    assert result.run_dir is None and list(tmp_path.iterdir()) == []
    assert seen == [0, 1]
    assert all(
        same(a[k], b[k]) for a, b in zip(result.history, on_disk.history) for k in untimed(a)
    )
    assert result.best_team == on_disk.best_team and result.species == on_disk.species


def test_to_pandas_and_its_error_without_pandas(runs, monkeypatch):
    _, result = runs
    pd = pytest.importorskip("pandas")
    df = result.to_pandas()
    assert isinstance(df, pd.DataFrame) and list(df.index) == [0, 1]
    assert df["fitness/best"].iloc[-1] == result.history[-1]["fitness/best"]
    monkeypatch.setitem(sys.modules, "pandas", None)  # as if it were not installed
    with pytest.raises(ImportError, match="pip install pandas"):
        result.to_pandas()


def test_resume_and_load(tmp_path):
    first = sc.evolve(
        generations=2, logdir=tmp_path, checkpoint_every=1, render_every=0, **SETTINGS
    )
    before = {f.name: f.stat().st_mtime_ns for f in first.run_dir.iterdir()}
    done = sc.resume(first.run_dir, render_every=0)  # nothing to do: no file changes
    assert done.generations == 2 and len(done.history) == 2
    assert {f.name: f.stat().st_mtime_ns for f in first.run_dir.iterdir()} == before
    result = sc.resume(first.run_dir, generations=3, render_every=0)
    assert result.run_dir == first.run_dir and result.config.generations == 3
    assert [h["generation"] for h in result.history] == [0, 1, 2]
    assert all(same(a[k], b[k]) for a, b in zip(result.history, first.history) for k in b)
    text = (first.run_dir / METRICS_FILE).read_text()
    assert text.count("generation,") == 1
    assert [r["generation"] for r in read_metrics_csv(first.run_dir / METRICS_FILE)[0]] == [0, 1, 2]
    loaded = sc.load(first.run_dir)
    assert loaded.evolution is None and loaded.best_team == result.best_team
    assert loaded.species == result.species and len(loaded.history) == 3
    # the same seed straight through: the same teams
    straight = sc.evolve(generations=3, logdir=tmp_path / "straight", render_every=0, **SETTINGS)
    assert (straight.run_dir / "teams.jsonl").read_text() == (
        first.run_dir / "teams.jsonl"
    ).read_text()


def test_csv_reporter_drops_repeated_generations_on_resume(tmp_path):
    path = tmp_path / METRICS_FILE
    path.write_text("generation,fitness/best\n0,1.0\n1,2.0\n2,3.0\n3,4.0\n4,5")  # cut short
    rep = CsvReporter(tmp_path)
    rep.on_start(SimpleNamespace(state=SimpleNamespace(generation=2)))  # checkpoint at 2
    assert path.read_text() == "generation,fitness/best\n0,1.0\n1,2.0\n"
    from dataclasses import fields

    from swarmcode_torch.coevo.evolve import GenerationResult

    team = dict.fromkeys(
        (
            "fitness",
            "species",
            "niches",
            "cost",
            "deliveries",
            "deliveries_individual",
            "deliveries_collab",
            "energy_used",
        ),
        1.5,
    )
    result = GenerationResult(
        **{**{f.name: 1.5 for f in fields(GenerationResult)}, "generation": 2, "team": team}
    )
    rep.on_generation(None, result)  # a header without the new tags gets them
    rows, columns = read_metrics_csv(path)
    assert columns == ["generation", "fitness/best", *SCALAR_TAGS[1:]]
    assert [r["generation"] for r in rows] == [0, 1, 2]
    assert rows[0]["fitness/best"] == 1.0 and rows[0]["team/cost"] is None
    assert rows[2]["team/cost"] == 1.5
    assert path.read_text().count("generation,") == 1


def test_settings_are_checked_before_anything_is_written(tmp_path):
    with pytest.raises(TypeError, match="unknown setting.*populaton"):
        sc.evolve(populaton=4, logdir=tmp_path)
    with pytest.raises(ValueError, match="population"):
        sc.evolve(population=1, logdir=tmp_path)
    with pytest.raises(ValueError, match="unknown scenario"):
        sc.evolve(scenario="no-such-world", logdir=tmp_path)
    with pytest.raises(ValueError, match="checkpoint_every"):
        sc.evolve(checkpoint_every=0, logdir=tmp_path, **SETTINGS)
    with pytest.raises(
        ValueError, match="memory.*use a smaller population, trials or swarm_size$"
    ):  # the API's names, not the flags
        sc.evolve(**{**SETTINGS, "population": 10**6, "trials": 1000}, logdir=tmp_path)
    with pytest.raises(ValueError, match="not a run directory"):
        sc.resume(tmp_path / "absent")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", builtin_names())
def test_scenario_objects_round_trip_through_toml(name, tmp_path):
    s = load_scenario(name)
    path = tmp_path / "s.toml"
    path.write_text(scenario_to_toml(s))
    assert load_scenario(str(path)) == s


def test_custom_scenario_from_a_file_and_as_an_object(tmp_path):
    example = EXAMPLES / "three-niche.toml"
    tiny = {k: v for k, v in SETTINGS.items() if k != "scenario"}
    by_path = sc.evolve(scenario=example, generations=1, logdir=None, **tiny)
    assert by_path.config.scenario == str(example) and by_path.scenario.name == "three-niche"
    # a Scenario object, changed in code: the run directory keeps it as a TOML file
    s = replace(load_scenario(str(example)), name="three-niche-wide", arena=24.0)
    result = sc.evolve(scenario=s, generations=1, logdir=tmp_path, render_every=0, **tiny)
    assert result.run_dir.name.startswith("three-niche-wide__b900__3__")
    assert result.config.scenario == "three-niche-wide"
    assert load_scenario(str(result.run_dir / "scenario.toml")) == s  # the run's own copy
    resumed = sc.resume(result.run_dir, generations=2, render_every=0)
    assert resumed.generations == 2 and resumed.scenario == s
    assert sc.load(result.run_dir).scenario == s
    memory = sc.evolve(scenario=s, generations=1, logdir=None, **tiny)
    assert memory.scenario == s and memory.config.scenario == "three-niche-wide"
    assert memory.best_team == result.best_team
    bad = replace(s, packages=())
    with pytest.raises(ValueError, match="packages"):
        sc.evolve(scenario=bad, generations=1, logdir=tmp_path / "bad", **tiny)
    assert not (tmp_path / "bad").exists()


def test_examples_script_runs_its_scenario(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(
        sys,
        "argv",
        [
            "custom_scenario.py",
            "--generations",
            "1",
            "--population",
            "4",
            "--swarm-size",
            "3",
            "--ticks",
            "6",
            "--logdir",
            str(tmp_path),
        ],
    )
    runpy.run_path(str(EXAMPLES / "custom_scenario.py"), run_name="__main__")
    out = capsys.readouterr().out
    assert "three-niche" in out and "best team: fitness" in out
    run_dir = only_dir(tmp_path)
    assert json.loads((run_dir / "summary.json").read_text())["generation"] == 0


@pytest.mark.subprocess
def test_package_exports_and_cheap_import():
    code = (
        "import sys, swarmcode_torch as sc; "
        "heavy = sorted({m.split('.')[0] for m in sys.modules} & "
        "{'matplotlib', 'tensorboard', 'typer', 'rich', 'pandas', 'PIL'}); "
        "import swarmcode_torch.coevo.evolve as E; "
        "print(heavy, callable(sc.evolve), sc.evolve.__module__, hasattr(E, 'generation'), "
        "sc.__version__)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True
    ).stdout.split()
    assert out[:4] == ["[]", "True", "swarmcode_torch.app.api", "True"], out
    assert out[4] == sc.__version__
    for name in (
        "evolve",
        "resume",
        "load",
        "RunResult",
        "SwarmCoDeConfig",
        "Evolution",
        "load_scenario",
        "Scenario",
        "__version__",
    ):
        assert name in sc.__all__ and hasattr(sc, name)
    from swarmcode_torch.coevo.config import SwarmCoDeConfig

    assert SwarmCoDeConfig is sc.SwarmCoDeConfig
    assert not hasattr(sc, "EvolveConfig")  # the name before 0.3, removed (CHANGELOG, Unreleased)


@pytest.mark.subprocess
def test_python_dash_m_runs_the_cli():
    r = subprocess.run(
        [sys.executable, "-m", "swarmcode_torch", "--help"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    assert "evolve" in r.stdout and "Usage" in r.stdout


def test_run_names_say_what_differs():
    from swarmcode_torch.app.runs import run_dir_name

    when = 1767225600.0  # a fixed time: only the fields before it matter
    stamp = run_dir_name(SwarmCoDeConfig(), when).rsplit("__", 1)[1]
    assert (
        run_dir_name(SwarmCoDeConfig(scenario="four-niche", seed=3), when)
        == f"four-niche__3__{stamp}"
    )
    assert (
        run_dir_name(SwarmCoDeConfig(scenario="budget", budget=4000.0, seed=1), when)
        == f"budget__b4000__1__{stamp}"
    )
    assert (
        run_dir_name(
            SwarmCoDeConfig(scenario="examples/x.toml", budget=2500.5, objective="roi"), when
        )
        == f"x__b2500.5__roi__0__{stamp}"
    )


def test_a_run_records_its_software_device_and_commit(tmp_path):
    import platform
    import shutil

    import torch

    result = sc.evolve(generations=1, logdir=tmp_path, **{**SETTINGS, "budget": 3000.0})
    assert result.run_dir.name.startswith("one-niche__b3000__3__")
    sw = json.loads((result.run_dir / "summary.json").read_text())["software"]
    assert sw["swarmcode-torch"] == sc.__version__ and sw["torch"] == torch.__version__
    assert sw["device"] == f"cpu ({platform.machine()})"
    if (ROOT / ".git").exists() and shutil.which("git"):  # run from this checkout: its commit
        head = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--short=12", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        assert sw["commit"].removesuffix("+dirty") == head
    config = (result.run_dir / "config.toml").read_text().splitlines()
    assert (
        config[1] == f"# written by swarmcode-torch {sc.__version__}, torch {torch.__version__}, "
        f"device cpu ({platform.machine()})" + (f", commit {sw['commit']}" if sw["commit"] else "")
    )
    assert sc.load(result.run_dir).config.budget == 3000.0  # the comment is no setting


def test_api_preset_sets_the_papers_rules_under_explicit_settings(tmp_path):
    r = sc.evolve(
        preset="paper",
        scenario="one-niche",
        generations=1,
        population=6,
        swarm_size=4,
        trials=1,
        ticks=10,
        seed=1,
        logdir=None,
        partner_admission="substitute",
    )
    cfg = r.config
    assert (cfg.preset, cfg.partners_per_niche, cfg.quota_size_exponent) == ("paper", "all", None)
    assert cfg.partner_admission == "substitute"  # an explicit setting goes on top of the preset
    given = sc.evolve(
        SwarmCoDeConfig(quota_size_exponent=0.5),
        preset="paper",
        scenario="one-niche",
        generations=1,
        population=6,
        swarm_size=4,
        trials=1,
        ticks=10,
        logdir=None,
    ).config
    assert given.quota_size_exponent is None  # the preset's settings replace the config's
    with pytest.raises(ValueError, match="unknown preset"):
        sc.evolve(preset="fast", logdir=tmp_path)
    assert not any(tmp_path.iterdir())


def test_api_callbacks_are_annotated_with_what_they_receive():
    import typing

    from swarmcode_torch.coevo.evolve import GenerationResult

    for fn in (sc.evolve, sc.resume):
        hint = typing.get_type_hints(fn)["callback"]
        (callable_type,) = [a for a in typing.get_args(hint) if a is not type(None)]
        params, _ = typing.get_args(callable_type)
        assert params == [GenerationResult], (fn.__name__, hint)
        assert "GenerationResult" in fn.__doc__
