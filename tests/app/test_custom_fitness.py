"""A user fitness function through the API (`sc.evolve(fitness=fn)`, `sc.resume(..., fitness=fn)`)
and examples/custom_fitness.py."""

import json
import runpy
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

import swarmcode_torch as sc
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.runs import RunError
from swarmcode_torch.coevo.config import EvalConfig
from swarmcode_torch.coevo.evaluation import team_scores

ROOT = Path(__file__).resolve().parents[2]
TINY = dict(
    scenario="one-niche",
    population=4,
    swarm_size=3,
    trials=2,
    ticks=6,
    seed=3,
    device="cpu",
    compile=False,
)
CALLS = []


def doubled(metrics, cost, cfg):
    """The built-in score times two: every later step (gate, mean, EMA, quotas, tournaments)
    is scale-free, so the run is the built-in one with every fitness doubled."""
    CALLS.append((sorted(metrics), tuple(cost.shape), type(cfg)))
    return 2 * team_scores(metrics, cost, cfg)


def deliveries(metrics, cost, cfg):
    return metrics["delivered_individual"] + metrics["delivered_collab"] + 0.5


def test_a_user_fitness_replaces_the_team_score_and_the_rest_applies_to_it():
    CALLS.clear()
    base = sc.evolve(generations=3, logdir=None, **TINY)
    twice = sc.evolve(generations=3, logdir=None, fitness=doubled, **TINY)
    # once per generation for its evaluation, and for the re-evaluation of its best team on
    # reeval_trials (10) environments (not run again for a team that is the best already)
    assert [c[1] for c in CALLS].count((2 * 4 * 2,)) == 3
    assert {c[1] for c in CALLS} == {(2 * 4 * 2,), (10,)}
    assert twice.best_team["fitness"] == 2 * base.best_team["fitness"]
    keys, shape, kind = CALLS[0]
    assert "delivered_individual" in keys and "closeness" in keys and kind is EvalConfig
    assert shape == (2 * 4 * 2,)  # E = 2 (focal, baseline) * B * trials
    for a, b in zip(base.history, twice.history):
        assert b["fitness/best"] == 2 * a["fitness/best"]
        assert b["team/fitness"] == 2 * a["team/fitness"]
        assert b["team/deliveries"] == a["team/deliveries"]
    assert twice.species == base.species
    assert twice.config.fitness_function == "test_custom_fitness.doubled"
    assert base.config.fitness_function is None
    # the run calls the function through a check (copies of its arguments, bounded scores)
    assert twice.evolution.ctx.score_fn.__wrapped__ is doubled
    assert base.evolution.ctx.score_fn is team_scores


def test_a_custom_run_records_its_function_and_resume_needs_it(tmp_path):
    first = sc.evolve(
        generations=2,
        logdir=tmp_path / "a",
        checkpoint_every=1,
        render_every=0,
        fitness=deliveries,
        **TINY,
    )
    run = first.run_dir
    summary = json.loads((run / "summary.json").read_text())
    assert summary["fitness"] == "custom: test_custom_fitness.deliveries"
    assert (
        'fitness_function = "test_custom_fitness.deliveries"' in (run / "config.toml").read_text()
    )
    with pytest.raises(RunError, match="custom fitness function .*deliveries.*fitness=fn"):
        sc.resume(run, generations=3)
    r = CliRunner().invoke(app, ["evolve", "--resume", str(run), "--generations", "3"])
    assert r.exit_code == 2 and "custom fitness function" in r.output, r.output
    assert "Traceback" not in r.output
    resumed = sc.resume(run, generations=3, render_every=0, fitness=deliveries)
    assert resumed.generations == 3
    straight = sc.evolve(
        generations=3, logdir=tmp_path / "b", render_every=0, fitness=deliveries, **TINY
    )
    assert (run / "teams.jsonl").read_text() == (straight.run_dir / "teams.jsonl").read_text()
    assert sc.load(run).config.fitness_function == "test_custom_fitness.deliveries"
    # a run of the built-in fitness does not say so, and keeps it
    plain = sc.evolve(generations=1, logdir=tmp_path / "c", render_every=0, **TINY)
    assert "fitness" not in json.loads((plain.run_dir / "summary.json").read_text())
    assert "fitness_function" not in (plain.run_dir / "config.toml").read_text()
    with pytest.raises(RunError, match="built-in fitness"):
        sc.resume(plain.run_dir, generations=2, fitness=deliveries)


@pytest.mark.parametrize(
    "fn, error, needle",
    [
        (lambda m, c, cfg: c[:3], ValueError, "shape \\(16,\\), got \\(3,\\)"),
        (lambda m, c, cfg: [1.0] * c.numel(), TypeError, "must return a tensor"),
        (lambda m, c, cfg: c * float("nan"), ValueError, "NaN or infinite"),
        ("not a function", TypeError, "must be a function"),
    ],
)
def test_a_bad_fitness_function_is_a_clear_error(fn, error, needle):
    with pytest.raises(error, match=needle):
        sc.evolve(generations=1, logdir=None, fitness=fn, **TINY)


def test_the_command_line_cannot_name_a_fitness_function(tmp_path):
    r = CliRunner().invoke(
        app, ["evolve", "--set", "fitness_function=x.y", "--logdir", str(tmp_path)]
    )
    assert r.exit_code == 2 and "evolve(fitness=fn)" in r.output, r.output
    with pytest.raises(ValueError, match="give the function again"):
        sc.evolve(generations=1, logdir=None, fitness_function="x.y", **TINY)


def test_examples_custom_fitness_runs(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(
        sys,
        "argv",
        [
            "custom_fitness.py",
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
    runpy.run_path(str(ROOT / "examples" / "custom_fitness.py"), run_name="__main__")
    out = capsys.readouterr().out
    assert "fitness function: __main__.deliveries_only" in out and "best team: score" in out
    (run_dir,) = [d for d in tmp_path.iterdir() if d.is_dir()]
    assert (
        json.loads((run_dir / "summary.json").read_text())["fitness"]
        == "custom: __main__.deliveries_only"
    )


def test_examples_custom_fitness_by_weights_sets_the_table_iv_keys(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(
        sys,
        "argv",
        [
            "custom_fitness.py",
            "--weights",
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
    runpy.run_path(str(ROOT / "examples" / "custom_fitness.py"), run_name="__main__")
    out = capsys.readouterr().out
    assert "fitness function: built-in, weights w_delivery=100 w_pickup=0 w_closeness=0" in out
    (run_dir,) = [d for d in tmp_path.iterdir() if d.is_dir()]
    config = (run_dir / "config.toml").read_text()
    assert "w_pickup = 0.0" in config and "w_closeness = 0.0" in config


def test_resume_with_another_fitness_function_is_refused_and_changes_nothing(tmp_path):
    first = sc.evolve(
        generations=1,
        logdir=tmp_path,
        checkpoint_every=1,
        render_every=0,
        fitness=deliveries,
        **TINY,
    )
    run = first.run_dir
    before = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    with pytest.raises(RunError) as e:
        sc.resume(run, generations=2, render_every=0, fitness=doubled)
    msg = str(e.value)
    assert "\n" not in msg
    assert "test_custom_fitness.deliveries" in msg and "test_custom_fitness.doubled" in msg
    after = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    assert after == before  # config.toml still names deliveries
    assert sc.resume(run, generations=2, render_every=0, fitness=deliveries).generations == 2


def test_a_function_run_as_a_script_is_the_same_function_imported():
    from swarmcode_torch.app.checkpoints import same_function

    assert same_function("mymod.score", "mymod.score")
    assert same_function("__main__.score", "mymod.score")
    assert same_function("mymod.score", "__main__.score")
    assert not same_function("mymod.score", "mymod.other")
    assert not same_function("__main__.score", "mymod.other")
    assert not same_function("__main__.score", "__main__.other")


def test_a_resume_with_another_lambda_is_refused(tmp_path):
    """Two lambdas share the name `<lambda>`; the run records a hash of its function's code, so
    a resume with a different lambda is refused and one with the same code goes on."""
    from swarmcode_torch.app.checkpoints import same_function
    from swarmcode_torch.coevo.evaluation import score_fn_name

    def pair():
        return (
            lambda m, c, cfg: m["delivered_individual"] + 1.0,
            lambda m, c, cfg: m["delivered_individual"] * 2.0,
        )

    (a, b), (a2, _) = pair(), pair()
    assert a.__qualname__ == b.__qualname__  # the names alone cannot tell them apart
    assert score_fn_name(a) == score_fn_name(a2) != score_fn_name(b)
    assert same_function(score_fn_name(a), score_fn_name(a2))
    assert not same_function(score_fn_name(a), score_fn_name(b))
    # a run recorded before the hash: matched by name, as before
    assert same_function(score_fn_name(a).split("#")[0], score_fn_name(b))
    run = sc.evolve(
        scenario="one-niche",
        population=4,
        swarm_size=3,
        trials=1,
        ticks=6,
        generations=1,
        device="cpu",
        compile=False,
        logdir=tmp_path,
        fitness=a,
        progress=False,
    ).run_dir
    with pytest.raises(ValueError, match="was scored by"):
        sc.resume(run, generations=2, fitness=b, progress=False)
    assert sc.resume(run, generations=2, fitness=a2, progress=False).generations == 2
