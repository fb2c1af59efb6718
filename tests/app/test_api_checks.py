"""Hostile inputs (issue 29) through the API: its arguments are checked before any file is
written, and a user fitness cannot overflow or edit the records (docs/RELIABILITY.md)."""

from __future__ import annotations

import pytest
import torch
from hostilekit import _snapshot, tiny_run
from runkit import _copy_run  # the same copy of a run directory

import swarmcode_torch as sc


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    return tiny_run(tmp_path_factory)


# ====================================================================== the API
API = dict(
    scenario="one-niche",
    population=6,
    swarm_size=4,
    trials=1,
    ticks=10,
    seed=3,
    generations=2,
    device="cpu",
    compile=False,
    render_every=0,
)


def _api(tmp_path, **kw):
    import swarmcode_torch as sc

    return sc.evolve(logdir=tmp_path / "runs", **{**API, **kw})


@pytest.mark.parametrize(
    "kw,error",
    [
        (dict(callback=42), "callback must be a function"),
        (dict(reporters=[object()]), "has no on_start, on_generation, on_end"),
        (dict(reporters=5), "reporters must be a list"),
        (dict(checkpoint_every=2.5), "checkpoint_every must be an integer"),
        (dict(figure_every="3"), "figure_every must be an integer"),
        (dict(fitness="f"), "fitness must be a function"),
    ],
)
def test_the_api_checks_its_arguments_before_any_file_is_written(tmp_path, kw, error):
    with pytest.raises(TypeError, match=error):
        _api(tmp_path, **kw)
    assert not (tmp_path / "runs").exists()


def test_api_resume_refuses_zero_generations_and_a_bad_callback(finished_run, tmp_path):
    import swarmcode_torch as sc

    run = _copy_run(finished_run, tmp_path / "run")
    before = _snapshot(run)
    with pytest.raises(ValueError, match="generations must be an integer >= 1"):
        sc.resume(run, generations=0)
    with pytest.raises(TypeError, match="callback must be a function"):
        sc.resume(run, generations=3, callback="x")
    assert _snapshot(run) == before


def huge(metrics, cost, cfg):
    return torch.full_like(cost, 3e38)


def spend(metrics, cost, cfg):
    cost.mul_(1000.0)  # an in-place edit of what it was given
    metrics["delivered_individual"].add_(50.0)
    return -cost


def plain(metrics, cost, cfg):
    return -cost * 1000.0


def test_a_user_fitness_with_huge_scores_is_refused(tmp_path):
    with pytest.raises(ValueError, match="beyond the"):
        _api(tmp_path, fitness=huge)


def test_a_user_fitness_that_edits_its_arguments_in_place_changes_no_record(tmp_path):
    a = _api(tmp_path / "a", fitness=spend)
    b = _api(tmp_path / "b", fitness=plain)  # the same scores without the edits
    assert a.best_team["cost"] == b.best_team["cost"]
    assert a.best_team["deliveries"] == b.best_team["deliveries"]
    assert [h["team/cost"] for h in a.history] == [h["team/cost"] for h in b.history]
    assert a.config.fitness_function.endswith(".spend")


def test_a_reporter_subclass_overrides_only_what_it_needs(tmp_path):
    """`sc.Reporter` is the base of every built-in reporter; a subclass with one hook is a
    reporter (the others do nothing) and is told of every generation, then of the end."""
    from swarmcode_torch.app import api_progress, checkpoints, keep, report_wandb, summary, terminal
    from swarmcode_torch.app.reporting import CsvReporter, TensorBoardReporter

    for cls in (
        CsvReporter,
        TensorBoardReporter,
        report_wandb.WandbReporter,
        summary.SummaryReporter,
        checkpoints.CheckpointReporter,
        keep.KeepingCheckpoints,
        terminal.ProgressReporter,
        api_progress.History,
        api_progress.Progress,
    ):
        assert issubclass(cls, sc.Reporter), cls

    class Generations(sc.Reporter):
        def __init__(self):
            self.seen, self.ended = [], 0

        def on_generation(self, ev, result):
            self.seen.append(result.generation)

        def on_end(self, ev):
            self.ended += 1

    r = Generations()
    sc.evolve(
        scenario="one-niche",
        generations=3,
        population=6,
        swarm_size=3,
        trials=1,
        ticks=10,
        logdir=None,
        reporters=[r],
        progress=False,
    )
    assert r.seen == [0, 1, 2] and r.ended == 1
