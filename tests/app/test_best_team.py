"""An honest best team (#41, `app/best_team.py`): each generation's best team is re-evaluated on
`reeval_trials` fresh environments, and the run keeps the team of the highest re-evaluated mean
(summary.json, teams.jsonl, TensorBoard's best/ scalars, inspect, the sweep table, the replay
page, --patience), the same as `evaluate` gives; evolution is unchanged; a resume gives the same
records; runs written before it still load and resume as they ran."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch
from typer.testing import CliRunner

import swarmcode_torch as sc
from swarmcode_torch.app import best_team
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.evaluate import evaluate
from swarmcode_torch.app.reporting import best_scalars, read_metrics_csv
from swarmcode_torch.app.run_record import app_record
from swarmcode_torch.app.session import Bounds
from swarmcode_torch.app.summary import read_summary, read_teams
from swarmcode_torch.coevo.evaluation import team_scores

K = 4
TINY = dict(
    scenario="one-niche",
    population=6,
    swarm_size=4,
    trials=1,
    ticks=100,  # long enough that the environments give different scores
    seed=3,
    device="cpu",
    compile=False,
    render_every=0,
    figure_every=1000,
    threads=1,
)
NEW_FIELDS = (
    "best_fitness_sd",
    "best_fitness_ci95",
    "best_reeval_trials",
    "best_reeval_seeds",
    "best_single_trial_fitness",
    "best_single_trial_generation",
)


def _summary(run: Path) -> dict:
    return json.loads((run / "summary.json").read_text())


@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    """A run of 5 generations straight through, re-evaluating on K environments."""
    res = sc.evolve(
        generations=5, logdir=tmp_path_factory.mktemp("straight"), reeval_trials=K, **TINY
    )
    return res


def test_the_recorded_best_is_what_evaluate_gives_on_the_same_seeds(straight):
    run = straight.run_dir
    s = _summary(run)
    assert s["best_reeval_trials"] == K and s["best_reeval_seeds"] == [2_000_000, 2_000_000 + K - 1]
    ref = evaluate(run, generation=s["best_generation"], episodes=K, seed_start=2_000_000)
    f = ref.teams[0].fitness
    assert f.sd is not None and f.sd > 0  # the environments differ
    assert s["best_fitness"] == f.mean  # the same numbers, not just close
    assert s["best_fitness_sd"] == f.sd and s["best_fitness_ci95"] == [f.low, f.high]
    # every generation's team is re-evaluated (teams.jsonl), and the best is the highest mean
    teams = read_teams(run)
    means = {g: t["reeval"]["mean"] for g, t in teams.items()}
    assert s["best_fitness"] == max(means.values())
    assert s["best_generation"] == min(g for g, m in means.items() if m == max(means.values()))
    g = max(teams)
    last = evaluate(run, generation=g, episodes=K, seed_start=2_000_000)
    assert teams[g]["reeval"]["mean"] == last.fitness.mean
    # the highest single evaluation of the run, named as such
    single = max(t["fitness"] for t in teams.values())
    assert s["best_single_trial_fitness"] == single
    assert teams[s["best_single_trial_generation"]]["fitness"] == single
    assert teams[s["best_generation"]]["fitness"] == straight.best_team["single_trial_fitness"]
    assert straight.best_team["fitness"] == s["best_fitness"]


def test_evolution_is_the_same_with_and_without_reevaluation(straight):
    off = sc.evolve(generations=5, logdir=None, reeval_trials=0, **TINY)
    for a, b in zip(straight.history, off.history):
        for tag in ("fitness/best", "fitness/mean", "species/count", "team/fitness"):
            assert a[tag] == b[tag], tag
        assert math.isnan(b["team/fitness_reeval"]) and b["perf/reeval_seconds"] == 0.0
        assert a["perf/reeval_seconds"] > 0
    assert straight.species == off.species
    # without re-evaluation the best team is the highest single evaluation, as before
    assert off.best_team["fitness"] == max(r["team/fitness"] for r in off.history)
    assert "reeval" not in off.best_team


def test_scalars_inspect_and_the_replay_page_report_the_reevaluated_score(straight, tmp_path):
    run = straight.run_dir
    s = _summary(run)
    result = SimpleNamespace(best=app_record(straight.evolution).best)
    b = best_scalars(result)
    assert b["best/fitness"] == s["best_fitness"]
    assert [b["best/fitness_ci_lo"], b["best/fitness_ci_hi"]] == s["best_fitness_ci95"]
    assert b["best/single_trial_fitness"] == s["best_single_trial_fitness"]
    rows, _ = read_metrics_csv(run / "metrics.csv")
    teams = read_teams(run)
    assert [r["team/fitness_reeval"] for r in rows] == [
        teams[g]["reeval"]["mean"] for g in sorted(teams)
    ]
    out = CliRunner().invoke(app, ["inspect", str(run)])
    assert out.exit_code == 0, out.output
    text = " ".join(out.output.split())  # as wrapped to the terminal's width
    assert f"fitness {s['best_fitness']:.2f} (mean of {K} fresh environments, 95 % interval" in text
    assert "the highest single evaluation of the run" in text
    from swarmcode_torch.app.analysis import replay_run
    from swarmcode_torch.app.replay_page import decode_page

    path, _ = replay_run(run, html=True, ticks=3, out=tmp_path / "team.html")
    rec = decode_page(path.read_text())["record"]
    assert rec["fitness"] == s["best_fitness"] and rec["trials"] == K
    assert [rec["fitness_low"], rec["fitness_high"]] == s["best_fitness_ci95"]


def test_a_resumed_run_records_what_a_straight_run_does(straight, tmp_path):
    part = sc.evolve(generations=2, logdir=tmp_path, reeval_trials=K, checkpoint_every=1, **TINY)
    res = sc.resume(part.run_dir, generations=5, threads=1)
    a, b = _summary(straight.run_dir), _summary(res.run_dir)
    for key in ("best_fitness", "best_generation", *NEW_FIELDS, "designs"):
        assert a[key] == b[key], key
    assert read_teams(straight.run_dir) == read_teams(res.run_dir)
    assert app_record(straight.evolution).best == app_record(res.evolution).best
    ck = torch.load(res.run_dir / "checkpoint.pt", weights_only=True)
    assert ck["app"]["best"] == app_record(straight.evolution).best


class _Fake:
    """A re-evaluation that returns a given mean per team (by the designs' first radius)."""

    def __init__(self, means: dict[float, float]):
        self.means, self.k, self.seeds = means, K, best_team.reeval_seeds(0, K)
        self.calls = 0

    def __call__(self, designs):
        self.calls += 1
        m = self.means[designs[0]["radius"]]
        return {
            "mean": m,
            "sd": 1.0,
            "ci95": [m - 1, m + 1],
            "trials": K,
            "seeds": [2_000_000, 2_000_003],
        }


def _team(g: int, single: float, radius: float) -> dict:
    d = dict(effector="suction", radius=radius, chassis_tier=1, battery_tier=1, motor_tier=1)
    d.update(torque_point=0.5, battery_point=0.5, dominance=0.5, bt=[0], count=4)
    return {"generation": g, "fitness": single, "designs": [d]}


def _run_updates(monkeypatch, k: int, teams: list[dict], means: dict[float, float]):
    fake = _Fake(means)
    monkeypatch.setattr(best_team, "reevaluator", lambda ev: fake)
    ev = _FakeEvolution(cfg=SimpleNamespace(reeval_trials=k), state=SimpleNamespace())
    for t in teams:
        app_record(ev).best, _ = best_team.update(ev, t)
    return ev, fake


class _FakeEvolution(SimpleNamespace):
    """What `best_team.update` and `Bounds` read of an Evolution (a record can be kept beside
    it: a SimpleNamespace cannot be referred to weakly)."""

    __slots__ = ("__weakref__",)
    __hash__ = object.__hash__


def test_a_lucky_early_team_is_not_kept_over_a_better_one(monkeypatch):
    # generation 0: lucky in its one evaluation (100) but 10 on fresh environments; generation 1
    # scores 50 once and 40 re-evaluated; generation 2 90 once, 30 re-evaluated
    teams = [_team(0, 100.0, 0.1), _team(1, 50.0, 0.2), _team(2, 90.0, 0.3), _team(3, 60.0, 0.2)]
    means = {0.1: 10.0, 0.2: 40.0, 0.3: 30.0}
    ev, fake = _run_updates(monkeypatch, K, [dict(t) for t in teams], means)
    best = app_record(ev).best
    assert best["generation"] == 1 and best["fitness"] == 40.0
    assert best["single_trial_fitness"] == 50.0
    assert best["run_single_trial"] == {"fitness": 100.0, "generation": 0}
    assert fake.calls == 3  # generation 3's team is the best team already: not run again
    s = best_team.summary_fields(best)
    assert s["best_single_trial_fitness"] == 100.0 and s["best_fitness_ci95"] == [39.0, 41.0]
    # without re-evaluation: the lucky team, as before
    old, fake = _run_updates(monkeypatch, 0, [dict(t) for t in teams], means)
    assert app_record(old).best["generation"] == 0 and app_record(old).best["fitness"] == 100.0
    assert fake.calls == 0 and "reeval" not in app_record(old).best


def test_patience_counts_from_the_reevaluated_best(monkeypatch):
    # the single evaluations improve at generation 1 (a lucky team); the re-evaluated means never
    teams = [_team(0, 50.0, 0.1), _team(1, 100.0, 0.2), _team(2, 60.0, 0.3)]
    means = {0.1: 40.0, 0.2: 10.0, 0.3: 20.0}
    bounds = Bounds(patience=2)
    for k, stops in ((K, "patience"), (0, None)):
        ev, _ = _run_updates(monkeypatch, k, [dict(t) for t in teams], means)
        ev.state.generation = 3
        ev.done = False
        assert bounds.reached(ev, 0.0) == stops, k


def _lucky(at: int, evaluations: int):
    """A fitness function whose evaluation of generation `at` (the run's batch of `evaluations`
    team-episodes; a re-evaluation is another size) gives every team a bonus of 10,000."""
    seen = []

    def lucky_fitness(metrics, cost, cfg):
        f = team_scores(metrics, cost, cfg)
        if cost.shape[0] == evaluations:
            seen.append(1)
            if len(seen) == at + 1:
                f = f + 10_000.0
        return f

    return lucky_fitness


@pytest.mark.parametrize("k", [0, K])
def test_a_run_with_a_lucky_generation_reports_it_only_as_its_single_trial_maximum(k, tmp_path):
    n = 2 * TINY["population"] * TINY["trials"]
    res = sc.evolve(
        generations=6, logdir=tmp_path, reeval_trials=k, fitness=_lucky(1, n), patience=2, **TINY
    )
    s = _summary(res.run_dir)
    assert s["best_single_trial_fitness"] > 10_000 and s["best_single_trial_generation"] == 1
    stop = s["stop"]
    if k == 0:  # the lucky team is the best team, and patience counts from it
        assert s["best_fitness"] > 10_000 and s["best_generation"] == 1
        assert stop == {"reason": "patience", "generation": 4, "patience": 2, "best_generation": 1}
    else:  # its fresh environments are not lucky
        assert s["best_fitness"] < 10_000 and s["best_reeval_trials"] == K
        teams = read_teams(res.run_dir)
        assert s["best_fitness"] == max(t["reeval"]["mean"] for t in teams.values())
        # where patience stops it: two generations after the last new best re-evaluated mean
        best_at, expected = 0, {"reason": "generations", "generation": 6}
        for g in sorted(teams):
            if teams[g]["reeval"]["mean"] > teams[best_at]["reeval"]["mean"]:
                best_at = g
            if g < 5 and g - best_at >= 2:
                expected = dict(
                    reason="patience", generation=g + 1, patience=2, best_generation=best_at
                )
                break
        assert stop == expected


def _make_old(run: Path) -> None:
    """`run` as a version before re-evaluation wrote it: no reeval_trials in its configs, no
    re-evaluation in its records, metrics.csv without the new columns."""
    lines = (run / "config.toml").read_text().splitlines()
    (run / "config.toml").write_text(
        "\n".join(ln for ln in lines if not ln.startswith("reeval_trials")) + "\n"
    )
    ck = torch.load(run / "checkpoint.pt", weights_only=True)
    del ck["config"]["reeval_trials"]
    best = ck["app"]["best"]
    best["fitness"] = best.pop("single_trial_fitness")
    del best["reeval"], best["run_single_trial"]
    torch.save(ck, run / "checkpoint.pt")
    s = _summary(run)
    for key in NEW_FIELDS:
        del s[key]
    s["best_fitness"] = best["fitness"]
    (run / "summary.json").write_text(json.dumps(s))
    teams = [json.loads(x) for x in (run / "teams.jsonl").read_text().splitlines()]
    for t in teams:
        del t["reeval"]
    (run / "teams.jsonl").write_text("".join(json.dumps(t) + "\n" for t in teams))
    rows, cols = read_metrics_csv(run / "metrics.csv", raw=True)
    cols = [c for c in cols if c not in ("team/fitness_reeval", "perf/reeval_seconds")]
    text = ",".join(cols) + "\n" + "".join(",".join(str(r[c]) for c in cols) + "\n" for r in rows)
    (run / "metrics.csv").write_text(text)


def test_a_run_written_before_reevaluation_loads_and_resumes_as_it_ran(straight, tmp_path):
    part = sc.evolve(generations=2, logdir=tmp_path, reeval_trials=K, checkpoint_every=1, **TINY)
    run = tmp_path / "old"
    shutil.copytree(part.run_dir, run)
    _make_old(run)
    s = read_summary(run)
    assert "best_fitness_ci95" not in s
    out = CliRunner().invoke(app, ["inspect", str(run)])
    assert out.exit_code == 0 and "fresh environments" not in out.output, out.output
    loaded = sc.load(run)
    assert loaded.config.reeval_trials == 0 and "reeval" not in loaded.best_team
    res = sc.resume(run, generations=4, threads=1)
    assert res.config.reeval_trials == 0
    s = read_summary(run)
    assert s["best_reeval_trials"] == 0 and s["best_fitness_ci95"] is None
    assert s["best_fitness"] == s["best_single_trial_fitness"]
    assert s["best_fitness"] == max(t["fitness"] for t in read_teams(run).values())
    rows, cols = read_metrics_csv(run / "metrics.csv")
    assert [r["generation"] for r in rows] == [0, 1, 2, 3]
    assert "team/fitness_reeval" in cols and rows[0]["team/fitness_reeval"] is None


def test_a_branch_that_turns_reevaluation_on_reevaluates_its_parents_best(tmp_path):
    parent = sc.evolve(generations=2, logdir=tmp_path, reeval_trials=0, checkpoint_every=1, **TINY)
    branch = sc.evolve(
        from_run=str(parent.run_dir),
        generations=3,
        reeval_trials=K,
        logdir=tmp_path,
        **{k: v for k, v in TINY.items() if k in ("render_every", "figure_every", "threads")},
    )
    best = app_record(branch.evolution).best
    assert best["reeval"]["trials"] == K
    ref = evaluate(branch.run_dir, team="best", episodes=K, seed_start=2_000_000)
    assert best["fitness"] == ref.fitness.mean


def test_the_sweep_table_shows_the_interval(tmp_path):
    from swarmcode_torch.app.sweep import csv_text, markdown, table_rows

    def summary(name, fit, ci, k=K):
        d = tmp_path / name
        d.mkdir()
        s = json.loads(json.dumps(_BASE))
        s.update(best_fitness=fit, best_fitness_ci95=ci, best_reeval_trials=k)
        (d / "summary.json").write_text(json.dumps(s))
        return d

    one = table_rows([(3000.0, 0, summary("a", 100.0, [90.0, 110.0]))])
    md = markdown(one)
    assert "| 3000 | 100.0 [90.0, 110.0] |" in md and f"over {K} fresh environments" in md
    two = table_rows(
        [
            (3000.0, 0, summary("b", 100.0, [90.0, 110.0])),
            (3000.0, 1, summary("c", 200.0, [170.0, 230.0])),
        ]
    )
    assert "150.0 ± 70.7 (CI ± 20.0)" in markdown(two)
    head, row = csv_text(two).splitlines()
    assert head.endswith(
        "best_reeval_trials,best_fitness_ci_lo,best_fitness_ci_hi,best_fitness_ci_half"
    )
    assert row.endswith(f"{K},130.0,170.0,20.0")


_BASE = dict(
    best_fitness=100.0,
    team_cost=2500.0,
    deliveries=4.0,
    deliveries_individual=4.0,
    deliveries_collab=0.0,
    energy_used=50.0,
    num_species=1,
    best_generation=0,
    budget=None,
    designs=[
        dict(
            effector="suction",
            radius=0.2,
            chassis_tier=1,
            battery_tier=1,
            motor_tier=1,
            torque_point=0.5,
            battery_point=0.5,
            dominance=0.5,
            cost=500.0,
            bt=[0],
            count=4,
            species=0,
        )
    ],
)


def test_a_summary_with_damaged_reevaluation_figures_is_refused(tmp_path):
    from swarmcode_torch.app.files import RunError

    for key, bad in (
        ("best_fitness_ci95", [1.0]),
        ("best_fitness_sd", "x"),
        ("best_reeval_seeds", "a"),
    ):
        d = tmp_path / key
        d.mkdir()
        (d / "summary.json").write_text(json.dumps({**_BASE, key: bad}))
        with pytest.raises(RunError, match=key):
            read_summary(d)


def test_reevaluation_seeds_stay_apart_from_the_run_seed():
    assert best_team.reeval_seeds(3, 10) == range(2_000_000, 2_000_010)
    assert best_team.reeval_seeds(2_000_004, 10) == range(2_000_005, 2_000_015)
    assert 2_000_004 not in best_team.reeval_seeds(2_000_004, 10)
