"""`swarmcode-torch evaluate RUN` and `swarmcode_torch.evaluate`: a run's team on fresh seeds in
one batch (batched = one episode at a time), deterministic, seeds apart from the run's, the
knock-outs, one-line errors, the JSON, and a run directory left as it was."""

from __future__ import annotations

import hashlib
import json
import math
import os
from pathlib import Path

import pytest
import torch
from replaykit import design
from test_reliability import _copy_run
from test_reliability import finished_run as made_run  # noqa: F401 - a fixture (one-niche, 4 robots, seed 3)
from typer.testing import CliRunner

import swarmcode_torch as sc
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.evaluate import MAX_EPISODES, Stat, evaluate, t_quantile
from swarmcode_torch.app.files import RunError
from swarmcode_torch.app.summary import read_teams

runner = CliRunner()
TICKS = 100  # the run's 10 ticks deliver nothing: long enough that episodes differ
RUN_SEED = 3

#: a team of three designs with robots and one without; design 0 is the focal, whose recorded
#: baseline refilled its 3 slots with 2 robots of design 1 and 1 of design 2
DESIGNS = [
    design("pincher", 0.3, count=3, species=3, focal=True, baseline_count=0),
    design(
        "suction",
        0.25,
        count=2,
        program="forage_random",
        species=7,
        dominance=0.2,
        baseline_count=4,
    ),
    design(
        "pincher",
        0.45,
        (3, 3, 3),
        count=1,
        program="collaborative",
        species=9,
        dominance=0.9,
        baseline_count=2,
    ),
    design("suction", 0.2, count=0, species=11, baseline_count=0),
]


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def digest(run: Path) -> dict[str, str]:
    return {
        str(p.relative_to(run)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(run.rglob("*"))
        if p.is_file()
    }


@pytest.fixture(scope="module")
def run(made_run):  # noqa: F811 - test_reliability's tiny run, by the name used here
    return made_run


@pytest.fixture(scope="module")
def team_run(run, tmp_path_factory):
    """A copy of the tiny run whose best team (summary.json) is DESIGNS."""
    to = _copy_run(run, tmp_path_factory.mktemp("team") / "run")
    s = json.loads((to / "summary.json").read_text())
    s["designs"] = DESIGNS
    (to / "summary.json").write_text(json.dumps(s))
    return to


def test_t_quantiles():
    for df, want in ((1, 12.7062), (2, 4.3027), (5, 2.5706), (10, 2.2281), (30, 2.0423)):
        assert t_quantile(0.975, df) == pytest.approx(want, abs=1e-4)
    assert t_quantile(0.975, 1e7) == pytest.approx(1.95996, abs=1e-5)
    s = Stat.of([1.0, 2.0, 3.0, 4.0])
    half = t_quantile(0.975, 3) * math.sqrt(5 / 3) / 2
    assert (s.mean, s.n) == (2.5, 4) and s.sd == pytest.approx(math.sqrt(5 / 3))
    assert (s.low, s.high) == (pytest.approx(2.5 - half), pytest.approx(2.5 + half))
    assert Stat.of([7.0]) == Stat(7.0, None, None, None, 1)


def test_the_batch_gives_each_episodes_own_numbers(team_run):
    """The mean of N episodes in one batch is the mean of N evaluations of one episode each,
    with the same seeds; each episode's fitness and each knock-out are the same."""
    n, start = 4, 2_000_000
    batched = evaluate(team_run, episodes=n, seed_start=start, ticks=TICKS)
    singles = [evaluate(team_run, episodes=1, seed_start=start + i, ticks=TICKS) for i in range(n)]
    t = batched.teams[0]
    assert t.fitness.sd is not None and t.fitness.sd > 0  # the episodes differ
    assert t.episode_fitness == [s.teams[0].episode_fitness[0] for s in singles]  # exactly
    assert t.fitness.mean == pytest.approx(sum(s.fitness.mean for s in singles) / n)
    for k, c in enumerate(batched.contributions):
        each = [s.contributions[k].contribution.mean for s in singles]
        assert c.contribution.mean == pytest.approx(sum(each) / n)
    for j, d in enumerate(batched.deliveries):
        assert d["mean"] == pytest.approx(sum(s.deliveries[j]["mean"] for s in singles) / n)
    assert batched.seeds == (start, start + n - 1)


def test_the_same_run_and_options_give_the_same_numbers(team_run):
    seen = []
    a = evaluate(team_run, episodes=3, ticks=TICKS)
    b = evaluate(team_run, episodes=3, ticks=TICKS, progress=lambda *a: seen.append(a))
    assert a.to_dict() == b.to_dict()  # the progress report changes nothing
    assert {s for s, _, _ in seen} == {"environments", "ticks"}
    assert seen[-1] == ("ticks", TICKS, TICKS)
    c = evaluate(team_run, episodes=3, ticks=TICKS, seed_start=5_000_000)
    assert c.teams[0].episode_fitness != a.teams[0].episode_fitness


def test_an_episode_runs_in_the_environment_replay_shows_for_its_seed(team_run):
    from swarmcode_torch.app.evaluate import _layouts
    from swarmcode_torch.app.render import record_episode, team_genome

    world = sc.load_scenario(str(team_run / "scenario.toml"))
    genome, team = team_genome(DESIGNS)
    seeds = [1_000_000, 1_000_001, 7]
    batch = _layouts(world, int(team.numel()), seeds, None)
    for i, seed in enumerate(seeds):
        shown = record_episode(genome, team, world, seed, ticks=0).layout
        for a, b in zip(batch, shown):
            assert torch.equal(a[i : i + 1], b)


def test_a_run_scored_by_a_custom_fitness_needs_it(team_run, tmp_path):
    custom = _copy_run(team_run, tmp_path / "custom")
    with open(custom / "config.toml", "a") as f:
        f.write('fitness_function = "mymodule.deliveries"\n')
    with pytest.raises(RunError, match="custom fitness function"):
        evaluate(custom, episodes=2)

    def deliveries(m, cost, cfg):
        return m["delivered_individual"] + m["delivered_collab"]

    r = evaluate(custom, episodes=3, ticks=TICKS, fitness=deliveries)
    assert r.fitness_function.startswith("custom: ") and "deliveries" in r.fitness_function
    assert r.fitness.mean == pytest.approx(r.teams[0].deliveries_total.mean)


def test_seeds_are_apart_from_the_runs_own(run):
    r = evaluate(run, episodes=2)
    assert r.seeds == (1_000_000, 1_000_001) and r.seed_start == 1_000_000
    assert not r.seeds[0] <= RUN_SEED <= r.seeds[1]
    with pytest.raises(RunError, match="the run's own seed 3"):
        evaluate(run, episodes=10, seed_start=0)
    assert evaluate(run, episodes=3, seed_start=0 + RUN_SEED + 1).seeds == (4, 6)


def test_knockouts_one_per_design_in_the_team(team_run, tmp_path):
    r = evaluate(team_run, episodes=3, ticks=TICKS)
    cs = r.contributions
    # one per design with robots; design 3 has none, and no knock-out
    assert [c.design for c in cs] == [0, 1, 2]
    assert [c.species for c in cs] == [3, 7, 9] and [c.robots for c in cs] == [3, 2, 1]
    assert [c.refill for c in cs] == ["recorded baseline", "nearest partner", "nearest partner"]
    assert cs[0].focal and not cs[1].focal
    for c in cs:
        assert c.contribution.mean == pytest.approx(r.fitness.mean - c.knockout_fitness.mean)
    assert r.teams[0].species == 3 and r.teams[0].robots == 6
    # the paper's preset (partner_admission = "open"): the partners by dominance, drawn from the
    # episode's seed
    open_run = _copy_run(team_run, tmp_path / "open")
    cfg = (open_run / "config.toml").read_text()
    assert 'partner_admission = "substitute"' in cfg
    (open_run / "config.toml").write_text(
        cfg.replace('partner_admission = "substitute"', 'partner_admission = "open"')
    )
    o = evaluate(open_run, episodes=3, ticks=TICKS)
    assert [c.refill for c in o.contributions] == [
        "recorded baseline",
        "dominance draw",
        "dominance draw",
    ]
    assert o.contributions[0] == cs[0]
    # a team of one design: its knock-out leaves no robot
    alone = evaluate(run_copy_with(team_run, tmp_path / "alone", DESIGNS[1:2]), episodes=2)
    assert [c.refill for c in alone.contributions] == ["no partner"]


def run_copy_with(run: Path, to: Path, designs: list[dict]) -> Path:
    to = _copy_run(run, to)
    s = json.loads((to / "summary.json").read_text())
    s["designs"] = [dict(d, focal=False) for d in designs]
    for d in s["designs"]:
        d.pop("baseline_count", None)
    (to / "summary.json").write_text(json.dumps(s))
    return to


def test_last_generation_and_top_teams(run):
    records = read_teams(run)
    last = max(records)
    r = evaluate(run, team="last", episodes=2)
    assert r.selection == "last" and r.teams[0].generation == last
    assert r.teams[0].recorded_fitness == pytest.approx(records[last]["fitness"])
    g = evaluate(run, generation=0, episodes=2)
    assert g.selection == "generation 0" and g.teams[0].generation == 0
    top = evaluate(run, top=5, episodes=2)
    fits = [t.recorded_fitness for t in top.teams]
    assert 1 <= len(top.teams) <= min(5, len(records)) and fits == sorted(fits, reverse=True)
    keys = {json.dumps(records[t.generation]["designs"], sort_keys=True) for t in top.teams}
    assert len(keys) == len(top.teams)  # distinct teams
    assert max(fits) == pytest.approx(max(rec["fitness"] for rec in records.values()))


def test_another_scenario(team_run, tmp_path):
    r = evaluate(team_run, episodes=2, scenario="two-niche", ticks=20)
    assert r.scenario == "two-niche" and not r.own_scenario
    assert len(r.deliveries) == len(sc.load_scenario("two-niche").packages)
    small = tmp_path / "small.toml"
    text = (team_run / "scenario.toml").read_text()
    small.write_text(text.replace("num_robots = 20", "num_robots = 5"))
    with pytest.raises(RunError, match="cannot carry the team's 6"):
        evaluate(team_run, episodes=2, scenario=str(small))


def test_the_api_is_exported():
    assert sc.evaluate is evaluate and "evaluate" in sc.__all__
    assert "EvaluationResult" in sc.__all__


# ------------------------------------------------------------------ the command line
def one_line_error(result, *needles):
    assert result.exit_code != 0, result.output
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.output
    for n in needles:
        assert n in lines[0], result.output


@pytest.mark.parametrize(
    "args, needles",
    [
        (["--episodes", 0], ["--episodes must be in [1, 10000]"]),
        (["--episodes", MAX_EPISODES + 1], ["--episodes"]),
        (["--generation", 99], ["no record of generation 99", "generations 0..1"]),
        (["--generation", -1], ["--generation must be >= 0"]),
        (["--top", 0], ["--top must be in"]),
        (["--team", "last", "--generation", 1], ["give one of"]),
        (["--seed-start", -1], ["--seed-start"]),
        (["--seed-start", 0], ["the run's own seed 3"]),
        (["--scenario", "no-such-world"], ["unknown scenario"]),
        (["--ticks", 0], ["--ticks"]),
        (["--device", "tpu"], ["device"]),
        (["--episodes", "many"], ["--episodes", "integer"]),
    ],
)
def test_bad_options_give_one_line_errors(run, args, needles):
    one_line_error(invoke("evaluate", run, *args), *needles)


def test_bad_runs_and_outputs_give_one_line_errors(run, tmp_path):
    one_line_error(invoke("evaluate", tmp_path / "nowhere"), "is not a directory")
    damaged = _copy_run(run, tmp_path / "damaged")
    (damaged / "summary.json").write_text('{"designs": [')
    one_line_error(invoke("evaluate", damaged), "summary.json", "malformed JSON")
    (damaged / "summary.json").unlink()
    one_line_error(invoke("evaluate", damaged), "no summary.json")
    target = tmp_path / "target.json"
    target.write_text("keep")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    one_line_error(invoke("evaluate", run, "--json", link), "symbolic link")
    one_line_error(invoke("evaluate", run, "--json", tmp_path), "is a directory")
    if hasattr(os, "mkfifo"):
        os.mkfifo(tmp_path / "fifo")
        one_line_error(invoke("evaluate", run, "--json", tmp_path / "fifo"), "not a regular file")
    one_line_error(invoke("evaluate", run, "--json", tmp_path / "no" / "x.json"), "does not exist")
    assert target.read_text() == "keep"


def test_cli_prints_tables_writes_json_and_leaves_the_run_as_it_was(team_run, tmp_path):
    before = digest(team_run)
    out = tmp_path / "eval.json"
    r = invoke("evaluate", team_run, "--episodes", 3, "--ticks", TICKS, "--json", out)
    assert r.exit_code == 0, r.output
    for text in ("fitness", "95 % interval", "knock-outs", "recorded baseline", "Wrote"):
        assert text in r.stdout, r.stdout
    data = json.loads(out.read_text())
    api = evaluate(team_run, episodes=3, ticks=TICKS).to_dict()
    assert data == json.loads(json.dumps(api))
    assert len(data["teams"][0]["contributions"]) == 3
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".eval.json.")]
    # written again over the old file, atomically
    r = invoke("evaluate", team_run, "--episodes", 2, "--ticks", TICKS, "--json", out)
    assert r.exit_code == 0 and json.loads(out.read_text())["episodes"] == 2
    r = invoke("evaluate", team_run, "--top", 2, "--episodes", 2)
    assert r.exit_code == 0, r.output
    assert digest(team_run) == before
