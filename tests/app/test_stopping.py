"""Stops beyond --max-time and plain --patience (`app.stopping`): a callback that asks the run
to stop, early stopping on a chosen metric with a minimum improvement and a warm-up; and
--keep-checkpoints (`app.keep`): the last K checkpoints and the best one."""

import json
import math
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

import swarmcode_torch as sc
from swarmcode_torch.app.checkpoints import read_checkpoint
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.stopping import MetricStop, metric_names

API_TINY = dict(
    scenario="one-niche",
    population=6,
    swarm_size=4,
    trials=1,
    ticks=15,
    seed=3,
    device="cpu",
    compile=False,
    progress=False,
)
CLI_TINY = ["--scenario", "one-niche", "--population", "6", "--swarm-size", "4", "--trials", "1",
            "--ticks", "15", "--seed", "3", "--device", "cpu"]  # fmt: skip
runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def _summary(run_dir: Path) -> dict:
    return json.loads((run_dir / "summary.json").read_text())


# ------------------------------------------------------------------ the callback
@pytest.mark.parametrize("says, reason", [(True, "callback"), ("enough species", "enough species")])
def test_a_callback_that_returns_true_or_a_reason_stops_after_that_generation(
    tmp_path, says, reason
):
    seen = []

    def callback(result):
        seen.append(result.generation)
        return says if result.generation == 1 else None

    res = sc.evolve(logdir=tmp_path, generations=6, callback=callback, **API_TINY)
    assert seen == [0, 1] and res.generations == 2 and res.stopped == "callback"
    stop = _summary(res.run_dir)["stop"]
    assert stop == {"reason": "callback", "generation": 2, "callback": reason}
    assert read_checkpoint(res.run_dir / "checkpoint.pt")["generation"] == 2  # resumable
    more = sc.resume(res.run_dir, callback=lambda r: False, progress=False)
    assert more.generations == 6 and more.stopped is None


def test_the_progress_says_why_a_callback_stopped_the_run(capsys):
    res = sc.evolve(logdir=None, generations=6, callback=lambda r: "enough", progress=True,
                    **{k: v for k, v in API_TINY.items() if k != "progress"})  # fmt: skip
    assert res.stopped == "callback" and res.generations == 1
    out = capsys.readouterr().out.splitlines()
    assert (
        out[-1] == "Stopped after 1 generation (generation 0): the callback asked to stop: enough"
    )


def test_a_callback_returning_other_values_lets_the_run_go_on():
    values = iter([None, False, 0, 1, ""])
    res = sc.evolve(logdir=None, generations=5, callback=lambda r: next(values), **API_TINY)
    assert res.generations == 5 and res.stopped is None


# ------------------------------------------------------------------ early stopping on a metric
def test_metric_stop_counts_improvements_beyond_min_delta_after_the_warmup():
    s = MetricStop(patience=2, metric="fitness/mean", min_delta=0.5, warmup=1)
    for g, v in enumerate([9.0, 1.0, 1.4, 1.6, math.nan, 2.0]):
        s.observe(g, v)
    # 9.0 is in the warm-up; 1.0 is the first watched; 1.4 is within 0.5; 1.6 is beyond
    assert (s.best, s.best_generation) == (1.6, 3)
    s = MetricStop(patience=2, metric="fitness/mean", min_delta=1.0, mode="min")
    for g, v in enumerate([5.0, 4.5, 3.9, 3.5]):
        s.observe(g, v)
    assert (s.best, s.best_generation) == (3.9, 2)


def test_a_metric_that_stalls_stops_the_run_after_warmup_plus_patience(tmp_path):
    # team/budget is the run's budget every generation: it never improves once watched
    r = invoke("evolve", *CLI_TINY, "--budget", 3000, "--generations", 30, "--logdir", tmp_path,
               "--patience", 2, "--stop-metric", "team/budget", "--stop-warmup", 3)  # fmt: skip
    assert r.exit_code == 0, r.output
    run_dir = next(tmp_path.iterdir())
    stop = _summary(run_dir)["stop"]
    # watched from generation 3, not improved at 4 and 5: stopped after generation 5
    assert stop["reason"] == "patience" and stop["generation"] == 3 + 2 + 1
    assert stop["metric"] == "team/budget" and stop["best_generation"] == 3
    assert "team/budget has not improved for 2 generations since generation 3" in r.output
    assert f"swarmcode-torch evolve --resume {run_dir}" in r.output


def test_min_delta_larger_than_any_change_stops_as_a_stall():
    res = sc.evolve(logdir=None, generations=30, patience=2, stop_metric="fitness/mean",
                    stop_min_delta=1e9, **API_TINY)  # fmt: skip
    assert res.stopped == "patience" and res.generations == 3


def test_resumed_metric_stop_reads_the_earlier_generations_back(tmp_path):
    kw = dict(patience=3, stop_metric="team/budget", budget=3000.0, **API_TINY)
    first = sc.evolve(logdir=tmp_path, generations=2, **kw)
    assert first.stopped is None
    more = sc.resume(first.run_dir, generations=30, patience=3, stop_metric="team/budget",
                     progress=False)  # fmt: skip
    assert more.stopped == "patience" and more.generations == 4  # counted from generation 0


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--stop-metric", "team/fitness"], "--stop-metric needs --patience K"),
        (["--patience", 2, "--stop-metric", "nope"], "unknown metric 'nope'"),
        (["--patience", 2, "--stop-min-delta", -1], "--stop-min-delta must be a finite number"),
        (["--patience", 2, "--stop-warmup", -1], "--stop-warmup must be >= 0"),
        (["--patience", 2, "--stop-mode", "up"], "--stop-mode must be max or min"),
        (["--keep-checkpoints", -1], "--keep-checkpoints must be >= 0"),
    ],
)
def test_bad_stop_options_are_one_line_errors(tmp_path, args, needle):
    r = invoke("evolve", *CLI_TINY, "--logdir", tmp_path, *args)
    assert r.exit_code != 0 and "Traceback" not in r.output
    assert needle in r.output, r.output
    assert not any(tmp_path.iterdir())


def test_metric_names_are_the_best_team_and_the_csv_tags():
    assert metric_names()[0] == "best/fitness" and "team/fitness" in metric_names()
    with pytest.raises(ValueError, match="stop_metric: unknown metric"):
        sc.evolve(logdir=None, patience=1, stop_metric="x", **API_TINY)


# ------------------------------------------------------------------ --keep-checkpoints
def test_keep_checkpoints_keeps_the_last_k_and_the_best(tmp_path):
    r = invoke("evolve", *CLI_TINY, "--generations", 7, "--checkpoint-every", 2,
               "--keep-checkpoints", 2, "--logdir", tmp_path)  # fmt: skip
    assert r.exit_code == 0, r.output
    run_dir = next(tmp_path.iterdir())
    # checkpoints at 0 (the start), 2, 4, 6 and 7 (the end): the last two are kept
    files = sorted(p.name for p in (run_dir / "checkpoints").iterdir())
    assert files == ["best.pt", "generation-000006.pt", "generation-000007.pt"]
    latest = read_checkpoint(run_dir / "checkpoint.pt")
    assert latest["generation"] == 7
    assert torch.equal(
        read_checkpoint(run_dir / "checkpoints" / "generation-000007.pt")["fitness"],
        latest["fitness"],
    )
    best = read_checkpoint(run_dir / "checkpoints" / "best.pt")

    # the state written right after the generation that found the run's best team
    # (less the run's highest single evaluation, which may rise after the best team is found)
    def team(record):
        return {k: v for k, v in record.items() if k != "run_single_trial"}

    assert team(best["app"]["best"]) == team(latest["app"]["best"])
    assert best["generation"] == latest["app"]["best"]["generation"] + 1
    r = invoke("evolve", "--resume", run_dir, "--generations", 9, "--checkpoint-every", 2,
               "--keep-checkpoints", 2)  # fmt: skip
    assert r.exit_code == 0, r.output
    files = sorted(p.name for p in (run_dir / "checkpoints").iterdir())
    assert files == ["best.pt", "generation-000008.pt", "generation-000009.pt"]
    assert read_checkpoint(run_dir / "checkpoint.pt")["generation"] == 9
