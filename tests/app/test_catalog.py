"""A scenario's own hardware catalog: parsing and checking it, the scenario key that names it,
every phenotype built from it (evaluation, records, replay, shards), and a run that keeps it."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest
import tomllib
import torch
from test_reliability import MINE, invoke, one_line_error

import swarmcode_torch as sc
from swarmcode_torch.app import distributed
from swarmcode_torch.app.render import record_episode, team_genome
from swarmcode_torch.app.runconfig import scenario_to_toml
from swarmcode_torch.app.runs import hardware_bytes, read_config, run_scenario
from swarmcode_torch.app.runs import resume as resume_run
from swarmcode_torch.coevo import evaluation
from swarmcode_torch.coevo.population import genome_phenotype
from swarmcode_torch.sim.hardware import (
    CatalogError,
    catalog_from_dict,
    catalog_tables,
    default_catalog,
    default_catalog_bytes,
    parse_catalog,
)
from swarmcode_torch.sim.scenario import ScenarioError, load_scenario, parse_scenario

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"

#: test_reliability's custom world, its robots built from catalog.toml beside it
SCENARIO = MINE.replace('name = "mine"', 'name = "dear"').replace(
    "episode_ticks = 10\n", 'episode_ticks = 20\nhardware = "catalog.toml"\n'
)


def _catalog_text(base_cost: float = 1045.0, force=None) -> str:
    """The built-in catalog file with its base cost (and motor forces) changed."""
    text = default_catalog_bytes().decode()
    text = re.sub(r"(?m)^cost = 45\.0", f"cost = {base_cost!r}", text, count=1)
    if force is not None:
        text = re.sub(r"(?m)^force = \[[^\]]*\]", f"force = {force!r}", text, count=1)
    assert text != default_catalog_bytes().decode()
    return text


@pytest.fixture
def dear(tmp_path):
    """A scenario file naming catalog.toml beside it, whose robots cost $1,000 more each."""
    (tmp_path / "catalog.toml").write_text(_catalog_text())
    (tmp_path / "dear.toml").write_text(SCENARIO)
    return tmp_path / "dear.toml"


def test_the_builtin_catalog_round_trips_through_its_tables():
    cat = default_catalog()
    assert catalog_from_dict(catalog_tables(cat)) == cat
    assert cat.base_cost == 45.0 and cat.motor_force == (40.0, 70.0, 110.0)


@pytest.mark.parametrize(
    "edit,field",
    [
        (lambda d: d.pop("motor"), r"\[motor\]: missing"),
        (lambda d: d["base"].pop("cost"), "base.cost: missing"),
        (lambda d: d["base"].update(colour=1.0), "base.colour: unknown field"),
        (lambda d: d.update(wheels={}), "wheels: unknown section"),
        (lambda d: d["motor"].update(force=[1.0, 2.0]), "motor.force: expected a list of 3"),
        (lambda d: d["motor"].update(force=[1.0, True, 2.0]), "motor.force: expected a list of 3"),
        (
            lambda d: d["motor"].update(efficiency=[0.0, 0.5, 0.8]),
            r"motor.efficiency: .*in \(0, 1\]",
        ),
        (lambda d: d["motor"].update(force_floor=1.5), r"motor.force_floor: .*in \[0, 1\]"),
        (lambda d: d["battery"].update(capacity=[1.0, -2.0, 3.0]), "battery.capacity"),
        (lambda d: d["chassis"].update(strength=[1.0, float("nan"), 3.0]), "chassis.strength"),
        (lambda d: d["base"].update(mass="heavy"), "base.mass: expected a number"),
        (lambda d: d.update(base=3), r"\[base\]: expected a table"),
    ],
)
def test_a_bad_catalog_names_its_field(edit, field):
    d = catalog_tables(default_catalog())
    edit(d)
    with pytest.raises(CatalogError, match=f"my.toml: {field}"):
        catalog_from_dict(d, "my.toml")


def test_catalog_bytes_that_are_not_toml_or_not_text_are_named():
    with pytest.raises(CatalogError, match="x.toml: not valid TOML"):
        parse_catalog(b"[base\nmass = 1", "x.toml")
    with pytest.raises(CatalogError, match="x.toml: not UTF-8 text"):
        parse_catalog(b"\xff\xfe\x00", "x.toml")


def test_a_scenario_finds_its_catalog_beside_it_from_any_working_directory(
    dear, tmp_path, monkeypatch
):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    s = load_scenario(str(dear))
    assert s.hardware == parse_catalog(_catalog_text().encode(), "c")
    assert s.hardware.base_cost == 1045.0 and s.hardware != default_catalog()
    assert load_scenario("four-niche").hardware == default_catalog()
    # an inline table is the same catalog
    inline = SCENARIO.replace('hardware = "catalog.toml"\n', "") + "\n".join(
        f"[hardware.{k}]\n" + "\n".join(f"{kk} = {vv!r}" for kk, vv in v.items()) + "\n"
        for k, v in catalog_tables(s.hardware).items()
    )
    assert parse_scenario(inline.encode(), "inline").hardware == s.hardware
    # a catalog given to the loader wins over the one the scenario names
    assert load_scenario(str(dear), default_catalog()).hardware == default_catalog()


def test_a_missing_or_bad_catalog_is_a_scenario_error_naming_it(dear):
    (dear.parent / "catalog.toml").write_text(
        _catalog_text().replace("force_floor = 0.35", "force_floor = 2.0")
    )
    with pytest.raises(
        ScenarioError,
        match=r"dear.toml: hardware \(.*catalog.toml\): "
        r"motor.force_floor",
    ):
        load_scenario(str(dear))
    (dear.parent / "catalog.toml").unlink()
    with pytest.raises(ScenarioError, match="hardware: catalog file not found: .*catalog.toml"):
        load_scenario(str(dear))
    with pytest.raises(ScenarioError, match="hardware: expected a file name or a table"):
        parse_scenario(SCENARIO.replace('"catalog.toml"', "3").encode(), "s")
    with pytest.raises(ScenarioError, match="no folder"):  # bytes with no file around them
        parse_scenario(SCENARIO.encode(), "s")
    r = invoke(
        "evolve",
        "--scenario",
        dear,
        "--generations",
        1,
        "--population",
        4,
        "--trials",
        1,
        "--logdir",
        dear.parent / "runs",
        "--device",
        "cpu",
    )
    one_line_error(r, "catalog file not found")
    assert not (dear.parent / "runs").exists()  # nothing made for a run that cannot start


def test_every_phenotype_of_a_run_is_built_from_its_scenarios_catalog(dear):
    """Team cost in the evaluation, the recorded designs' cost and capability, the replayed
    robots and a shard's rollout: each uses the scenario's catalog, not the built-in one."""
    result = sc.evolve(
        scenario=str(dear),
        generations=2,
        population=6,
        trials=1,
        device="cpu",
        compile=False,
        logdir=dear.parent / "runs",  # not the checkout's runs/ (the default)
    )
    scen = load_scenario(str(dear))
    best = result.best_team
    genome, team = team_genome(best["designs"], result.config.tag_length)
    own = genome_phenotype(genome, scen.hardware)
    builtin = genome_phenotype(genome, default_catalog())
    assert torch.allclose(own.cost, builtin.cost + 1000.0)
    # the records round genes to 4 decimals and costs to cents: the same cost to 1e-4
    assert [d["cost"] for d in best["designs"]] == pytest.approx(own.cost.tolist(), rel=1e-4)
    counts = torch.tensor([d["count"] for d in best["designs"]], dtype=torch.float)
    assert best["cost"] == pytest.approx(float((own.cost * counts).sum()), abs=0.5)
    assert best["cost"] > 1000.0 * scen.num_robots

    # the episode's robots: the same mass and force as the evaluation's, from the catalog
    heavy = dataclasses.replace(
        scen, hardware=catalog_from_dict(tomllib.loads(_catalog_text(force=[1.0, 2.0, 3.0])))
    )
    teams = torch.as_tensor(team).view(1, -1)
    assert torch.equal(
        evaluation.team_robots(genome, teams, heavy.hardware).force,
        genome_phenotype(genome, heavy.hardware).force[teams],
    )
    assert not torch.equal(
        evaluation.team_robots(genome, teams, heavy.hardware).force,
        evaluation.team_robots(genome, teams).force,
    )
    ep = record_episode(genome, torch.as_tensor(team), heavy, seed=0, ticks=3)
    assert ep is not None

    # a shard builds its robots from the catalog its spec carries
    ev = sc.Evolution(dataclasses.replace(result.config, generations=3), scenario=heavy)
    plan = evaluation.plan_evaluation(
        ev.state.genome,
        torch.zeros(6, dtype=torch.long),
        torch.zeros(1, dtype=torch.long),
        torch.zeros(1, dtype=torch.long),
        ev.state.fitness,
        ev.state.has_fitness,
        heavy,
        ev.ctx.eval_cfg,
        torch.Generator().manual_seed(0),
    )
    batch = evaluation.sim_batch(plan, ev.state.genome)
    spec = distributed.ShardSpec(
        params=ev.ctx.params,
        ticks=5,
        device="cpu",
        compiled=False,
        cuda_graphs=False,
        cuda_graphs_required=False,
        threads=1,
        hardware=heavy.hardware,
    )
    m, _ = distributed.unpack_metrics(
        distributed.EvalShard(spec).simulate(distributed.pack_batch(batch))
    )
    here, _ = evaluation.simulate_batch(batch, ev.ctx.params, 5, catalog=heavy.hardware)
    assert all(torch.equal(m[k], here[k]) for k in here)
    assert heavy.hardware != default_catalog()


def test_a_run_keeps_its_catalog_and_resumes_and_replays_with_it(dear, tmp_path):
    r = invoke(
        "evolve",
        "--scenario",
        dear,
        "--generations",
        2,
        "--population",
        6,
        "--trials",
        1,
        "--ticks",
        10,
        "--logdir",
        tmp_path / "runs",
        "--device",
        "cpu",
        "--no-compile",
        "--render-every",
        0,
    )
    assert r.exit_code == 0, r.output
    (run,) = (tmp_path / "runs").iterdir()
    kept = parse_catalog((run / "hardware.toml").read_bytes(), "copy")
    assert kept == load_scenario(str(dear)).hardware
    # the original catalog goes away, then comes back different: the run keeps its own
    (dear.parent / "catalog.toml").unlink()
    assert run_scenario(run, read_config(run)).hardware == kept
    (dear.parent / "catalog.toml").write_text(_catalog_text(base_cost=5.0))
    ev = resume_run(run, generations=3)
    assert ev.ctx.scenario.hardware == kept and ev.cfg.scenario == str(dear)
    r = invoke("evolve", "--resume", run, "--generations", 3, "--device", "cpu")
    assert r.exit_code == 0, r.output
    r = invoke("replay", run, "--ticks", 4, "--out", tmp_path / "t.gif")
    assert r.exit_code == 0, r.output
    # a damaged copy is named, never half-used
    (run / "hardware.toml").write_text("[base]\nmass = 1.0\n")
    one_line_error(
        invoke("evolve", "--resume", run, "--generations", 4, "--device", "cpu"),
        "hardware.toml",
        "[chassis]: missing",
    )


def test_a_run_on_the_builtin_catalog_keeps_the_installed_file_as_read():
    assert hardware_bytes() == hardware_bytes(default_catalog()) == default_catalog_bytes()
    other = dataclasses.replace(default_catalog(), base_cost=1.0)
    assert parse_catalog(hardware_bytes(other), "copy") == other


def test_a_scenario_object_with_its_own_catalog_round_trips_and_runs(dear):
    s = load_scenario(str(dear))
    text = scenario_to_toml(s)
    assert "[hardware.motor]" in text
    assert parse_scenario(text.encode(), "object") == s
    assert "[hardware" not in scenario_to_toml(load_scenario("four-niche"))
    result = sc.evolve(
        scenario=s,
        generations=1,
        population=4,
        trials=1,
        device="cpu",
        compile=False,
        logdir=dear.parent / "runs",
    )
    assert result.best_team["cost"] > 1000.0 * s.num_robots


def test_examples_scenario_with_its_own_catalog_loads_and_is_dearer():
    s = load_scenario(str(EXAMPLES / "three-niche-carbon.toml"))
    base = load_scenario(str(EXAMPLES / "three-niche.toml"))
    assert s.packages == base.packages and s.hardware != default_catalog()
    assert s.hardware == parse_catalog((EXAMPLES / "carbon-hardware.toml").read_bytes(), "p")


def test_examples_script_runs_the_scenario_with_its_own_catalog(tmp_path, monkeypatch, capsys):
    import runpy
    import sys

    monkeypatch.setattr(
        sys,
        "argv",
        [
            "custom_scenario.py",
            "--scenario",
            str(EXAMPLES / "three-niche-carbon.toml"),
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
    assert "three-niche-carbon" in out and "(160.0, 240.0, 360.0)" in out
    (run,) = tmp_path.iterdir()
    assert parse_catalog((run / "hardware.toml").read_bytes(), "copy") == parse_catalog(
        (EXAMPLES / "carbon-hardware.toml").read_bytes(), "example"
    )
