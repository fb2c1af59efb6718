"""Sweeps and sharded evaluation on Ray (swarmcode_torch.distributed), on one local Ray cluster
of 2 CPUs started once for the module; tiny CPU configs.

- a sweep of 2 budgets x 2 seeds on 2 Ray workers writes the in-process sweep's tables and runs;
- a run that fails is reported, the others finish, and the re-run completes it;
- a run whose worker is killed mid-way resumes from its checkpoint when the sweep is re-run,
  with the results of an uninterrupted run;
- an evolution evaluated in 2 shards on Ray actors equals the unsharded one (teams, summary,
  checkpoint), and shards of a batch score exactly like the whole batch (no Ray);
- without Ray the Ray options are one-line errors naming the extra.
"""

import json
import os
import signal
import sys
import threading
import time
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from swarmcode_torch.app import distributed
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.runs import RunLock, read_checkpoint
from swarmcode_torch.coevo import evaluation
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.evolve import Evolution
from swarmcode_torch.coevo.speciation import speciate

runner = CliRunner()
SIZE = [
    "--scenario",
    "one-niche",
    "--population",
    "7",
    "--swarm-size",
    "3",
    "--trials",
    "1",
    "--ticks",
    "6",
    "--no-compile",
    "--device",
    "cpu",
]
SWEEP = ["sweep", *SIZE, "--generations", "2", "--budgets", "300,600"]
RAY_EXTRA = 'pip install -e ".[ray]" in the source tree'


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def ok(result):
    assert result.exit_code == 0, result.output
    return result


@pytest.fixture(scope="module")
def ray_cluster():
    ray = pytest.importorskip("ray")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    ray.init(
        num_cpus=2, include_dashboard=False, log_to_driver=False, _node_ip_address="127.0.0.1"
    )  # loopback only
    yield ray
    ray.shutdown()


@pytest.fixture(scope="module")
def in_process_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("in_process") / "sweep"
    ok(invoke(*SWEEP, "--seeds", "0,1", "--out", out))
    return out


def runs_of(out: Path) -> list[str]:
    return sorted(p.name for p in out.iterdir() if p.is_dir())


@pytest.mark.subprocess
def test_sweep_on_ray_matches_in_process(ray_cluster, in_process_sweep, tmp_path):
    out = tmp_path / "sweep"
    r = ok(invoke(*SWEEP, "--seeds", "0,1", "--out", out, "--workers", 2))
    assert "finished (4 done, 0 running, 0 failed of 4)" in r.output
    for name in ("table.csv", "table.md"):
        assert (out / name).read_bytes() == (in_process_sweep / name).read_bytes(), name
    assert runs_of(out) == runs_of(in_process_sweep) and len(runs_of(out)) == 4
    for run in runs_of(out):
        for name in ("teams.jsonl", "config.toml"):
            assert (out / run / name).read_bytes() == (in_process_sweep / run / name).read_bytes()
        assert not (out / run / "run.lock").exists()
    assert not (out / "sweep.lock").exists()
    # run again: every run is done, nothing goes to Ray
    r = ok(invoke(*SWEEP, "--seeds", "0,1", "--out", out, "--workers", 2))
    assert r.output.count("already done") == 4 and "Ray:" not in r.output


@pytest.mark.subprocess
def test_failed_run_is_reported_the_others_finish(ray_cluster, in_process_sweep, tmp_path):
    out = tmp_path / "sweep"
    held = out / "budget-300_seed-0"
    held.mkdir(parents=True)
    with RunLock(held):  # a live holder: that run's worker cannot lock it
        r = invoke(*SWEEP, "--seeds", "0", "--out", out, "--workers", 2)
    assert r.exit_code == 2, r.output
    assert "budget-300_seed-0: failed:" in r.output and "in use by a live run" in r.output
    assert "1 of 2 runs failed (budget-300_seed-0)" in " ".join(r.output.split())
    assert "Traceback" not in r.output
    table = (out / "table.csv").read_text().splitlines()
    assert len(table) == 2 and table[1].startswith("600.0,1,")  # the run that finished
    ref = in_process_sweep / "budget-600_seed-0" / "teams.jsonl"
    assert (out / "budget-600_seed-0" / "teams.jsonl").read_bytes() == ref.read_bytes()
    r = ok(invoke(*SWEEP, "--seeds", "0", "--out", out, "--workers", 2))
    assert "budget-600_seed-0: already done" in r.output
    assert len((out / "table.csv").read_text().splitlines()) == 3
    ref = in_process_sweep / "budget-300_seed-0" / "teams.jsonl"
    assert (held / "teams.jsonl").read_bytes() == ref.read_bytes()


def _last_records(path: Path) -> dict:
    """generation -> its last record in teams.jsonl (a resume may repeat generations)."""
    return {json.loads(line)["generation"]: line for line in path.read_text().splitlines()}


def _summary(run: Path) -> dict:
    s = json.loads((run / "summary.json").read_text())
    # the results, not the software that made them (a commit made while the test runs
    # changes the checkout's commit between the two runs)
    s.pop("software")
    s["last_generation"] = {
        k: v for k, v in s["last_generation"].items() if not k.startswith("perf/")
    }
    return s


@pytest.mark.subprocess
def test_killed_worker_run_resumes_on_rerun(ray_cluster, tmp_path):
    args = [
        "sweep",
        *SIZE,
        "--generations",
        20,
        "--budgets",
        "300",
        "--seeds",
        "0",
        "--checkpoint-every",
        2,
    ]
    out = tmp_path / "sweep"
    run = out / "budget-300_seed-0"
    killed: list[int] = []

    def kill_worker_mid_run():
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                lines = (run / "teams.jsonl").read_text().count("\n")
                holder = (run / "run.lock").read_text()
            except OSError:
                lines, holder = 0, ""
            if lines >= 3 and "pid=" in holder:
                pid = int(holder.split("pid=")[1].split()[0])
                assert pid != os.getpid()  # the run is in a Ray worker
                os.kill(pid, signal.SIGKILL)
                killed.append(lines)
                return
            time.sleep(0.01)

    watcher = threading.Thread(target=kill_worker_mid_run)
    watcher.start()
    r = invoke(*args, "--out", out, "--workers", 2)
    watcher.join()
    assert killed, r.output
    assert r.exit_code == 2, r.output
    assert "budget-300_seed-0: failed:" in r.output and "Traceback" not in r.output
    assert read_checkpoint(run / "checkpoint.pt")["generation"] < 20
    r = ok(invoke(*args, "--out", out, "--workers", 2))
    assert "finished (1 done" in r.output
    # the same results as an uninterrupted run
    ref = tmp_path / "ref"
    ok(invoke(*args, "--out", ref))
    ref_run = ref / "budget-300_seed-0"
    assert _last_records(run / "teams.jsonl") == _last_records(ref_run / "teams.jsonl")
    assert _summary(run) == _summary(ref_run)
    assert (out / "table.csv").read_bytes() == (ref / "table.csv").read_bytes()


def _only_run(logdir: Path) -> Path:
    (run,) = list(logdir.iterdir())
    return run


@pytest.mark.subprocess
def test_sharded_evolution_equals_unsharded(ray_cluster, tmp_path):
    args = ["evolve", *SIZE, "--generations", 2, "--render-every", 0, "--budget", 400]
    ok(invoke(*args, "--logdir", tmp_path / "one"))
    r = ok(invoke(*args, "--logdir", tmp_path / "sharded", "--eval-workers", 2))
    assert "Evaluation: 2 shards on Ray actors" in r.output
    assert "KiB sent and" in r.output
    a, b = _only_run(tmp_path / "one"), _only_run(tmp_path / "sharded")
    assert (a / "teams.jsonl").read_bytes() == (b / "teams.jsonl").read_bytes()
    assert (a / "config.toml").read_bytes() == (b / "config.toml").read_bytes()
    assert _summary(a) == _summary(b)
    ca, cb = read_checkpoint(a / "checkpoint.pt"), read_checkpoint(b / "checkpoint.pt")
    assert ca.keys() == cb.keys()
    for k in ca:
        if isinstance(ca[k], torch.Tensor):
            assert torch.equal(ca[k], cb[k]), k
        elif isinstance(ca[k], dict) and k in ("genome", "proto", "admission"):
            assert all(torch.equal(ca[k][f], cb[k][f]) for f in ca[k]), k
        else:
            assert ca[k] == cb[k], k


class _InProcessShards:
    """The sharded evaluator's split, codec and gather, with the shards simulated here."""

    def __init__(self, ctx, shards):
        self.ctx, self.shards, self.sent = ctx, shards, 0

    def simulate(self, plan, genome):
        parts, secs = [], []
        for lo, hi in distributed.shard_bounds(plan.size, self.shards):
            data = distributed.pack_batch(evaluation.sim_batch(plan, genome, lo, hi))
            self.sent += len(data)
            m, s = evaluation.simulate_batch(
                distributed.unpack_batch(data),
                self.ctx.params,
                self.ctx.eval_cfg.ticks,
                self.ctx.step_fn,
            )
            m, s = distributed.unpack_metrics(distributed.pack_metrics(m, s))
            parts.append(m)
            secs.append(s)
        return evaluation.gather_metrics(parts), max(secs)


def test_shards_score_exactly_like_one_batch():
    ev = Evolution(
        SwarmCoDeConfig(
            scenario="four-niche",
            population=8,
            swarm_size=4,
            trials=2,
            ticks=10,
            generations=3,
            device="cpu",
            compile=False,
            budget=500.0,
        )
    )
    ev.step()  # species, elites and fitness to choose from
    st, ctx = ev.state, ev.ctx
    sp = speciate(
        st.genome,
        st.species_hint,
        st.proto,
        st.proto_ids,
        st.next_species_id,
        ctx.speciation.delta,
        w=ctx.speciation.weights,
    )
    call = (
        st.genome,
        sp.species,
        sp.proto_ids,
        sp.proto_index,
        st.fitness,
        st.has_fitness,
        ctx.scenario,
        ctx.eval_cfg,
    )
    plan = evaluation.plan_evaluation(*call, torch.Generator().manual_seed(1))
    run = (plan, st.genome, ctx.scenario, ctx.eval_cfg, ctx.params)
    whole = evaluation.evaluate(*run, ctx.step_fn)
    for shards in (2, 3):  # 3: shards of 2, 3 and 3 evaluations
        ev_shards = _InProcessShards(ctx, shards)
        res = evaluation.evaluate(*run, evaluator=ev_shards)
        for f in ("fitness", "focal", "baseline", "team_cost"):
            assert torch.equal(getattr(res, f), getattr(whole, f)), (shards, f)
        for k, v in whole.team_metrics.items():
            assert torch.equal(res.team_metrics[k], v), (shards, k)
        assert torch.equal(res.swarms.focal_team, whole.swarms.focal_team)
        assert ev_shards.sent > 0
    assert distributed.shard_bounds(7, 2) == [(0, 3), (3, 7)]
    assert distributed.shard_bounds(3, 5) == [(0, 1), (1, 2), (2, 3)]


def test_pack_is_lossless():
    g = torch.Generator().manual_seed(0)
    t = {
        "same_float": torch.tensor([[0.0, -0.0], [0.0, -0.0], [0.0, -0.0]]),
        "signed_zero": torch.tensor([[0.0], [-0.0]]),  # equal, not the same bits
        "nan": torch.tensor([float("nan"), float("nan")]),
        "long": torch.tensor([-1, 5, 300]),
        "big": torch.tensor([2**40, -3]),
        "bool": torch.rand(4, 3, generator=g) < 0.5,
        "empty": torch.zeros(0, 2, dtype=torch.long),
        "rows": torch.arange(6).reshape(2, 3).repeat(4, 1),
    }
    for name, x in t.items():
        y = distributed._unpack_tensor(distributed._pack_tensor(x))
        assert y.dtype == x.dtype and y.shape == x.shape, name
        assert torch.equal(
            x.view(torch.int32) if x.is_floating_point() else x,
            y.view(torch.int32) if y.is_floating_point() else y,
        ), name


def test_ray_options_without_ray_name_the_extra(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    for args in (
        ["sweep", *SIZE, "--workers", 2, "--out", tmp_path / "s"],
        ["sweep", *SIZE, "--ray-address", "auto", "--out", tmp_path / "s"],
        ["evolve", *SIZE, "--eval-workers", 2, "--logdir", tmp_path / "e"],
        ["evolve", *SIZE, "--ray-address", "auto", "--logdir", tmp_path / "e"],
    ):
        r = invoke(*args)
        assert r.exit_code == 2, r.output
        lines = [line for line in r.output.splitlines() if line.strip()]
        assert len(lines) == 1 and RAY_EXTRA in lines[0] and "needs Ray" in lines[0], r.output
    assert not (tmp_path / "s").exists() and not (tmp_path / "e").exists()
    for args, needle in (
        (["sweep", "--workers", 0], "--workers must be >= 1"),
        (["sweep", "--gpus-per-run", 0.5], "for runs on Ray"),
        (["evolve", "--eval-workers", 0], "--eval-workers must be >= 1"),
        (["evolve", "--cpus-per-eval-worker", 2], "evaluation shards on Ray"),
    ):
        r = invoke(*args)
        assert r.exit_code == 2 and needle in r.output, r.output
