"""The research workflow: snapshots and branching (--snapshot-every, --from), bounds
(--max-time, --patience), a config file for a new run (--config, --print-config), through the
command line and the API."""

import csv
import json
from pathlib import Path

import pytest
import tomllib
import torch
from typer.testing import CliRunner

import swarmcode_torch as sc
from swarmcode_torch.app import session
from swarmcode_torch.app.checkpoints import parse_run_ref, read_checkpoint
from swarmcode_torch.app.cli import app
from swarmcode_torch.coevo.config import SwarmCoDeConfig

runner = CliRunner()
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
    "--seed",
    "3",
    "--device",
    "cpu",
    "--no-compile",
    "--render-every",
    "0",
]
API_TINY = dict(
    scenario="one-niche",
    population=6,
    swarm_size=4,
    trials=1,
    ticks=15,
    seed=3,
    device="cpu",
    compile=False,
)


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def assert_clean_error(result, *needles):
    assert result.exit_code != 0
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1, result.output
    for n in needles:
        assert n in result.output, result.output


def new_run(logdir: Path, *args) -> Path:
    before = set(logdir.iterdir()) if logdir.exists() else set()
    r = invoke("evolve", *TINY, "--logdir", logdir, *args)
    assert r.exit_code == 0, r.output
    (made,) = set(logdir.iterdir()) - before
    return made


def rows(run_dir: Path) -> dict[int, dict]:
    """metrics.csv by generation, less the timings."""
    with open(run_dir / "metrics.csv", newline="") as f:
        return {
            int(r["generation"]): {k: v for k, v in r.items() if not k.startswith("perf/")}
            for r in csv.DictReader(f)
        }


def teams(run_dir: Path) -> dict[int, str]:
    out = {}
    for line in (run_dir / "teams.jsonl").read_text().splitlines():
        rec = json.loads(line)
        out[rec["generation"]] = json.dumps(rec, sort_keys=True)
    return out


def same_state(a: dict, b: dict) -> bool:
    """Two checkpoints hold the same evolution state (every tensor and value but the config)."""
    for key in ("generation", "next_species_id", "app", "history"):
        if a[key] != b[key]:
            return False
    for key in ("species_hint", "proto_ids", "fitness", "has_fitness", "rng_state"):
        if not torch.equal(a[key], b[key]):
            return False
    return all(torch.equal(a["genome"][k], b["genome"][k]) for k in a["genome"])


def config_toml(run_dir: Path) -> dict:
    return tomllib.loads((run_dir / "config.toml").read_text())


# ------------------------------------------------------------------ snapshots and branching
@pytest.fixture(scope="module")
def parent(tmp_path_factory):
    """A 6-generation run with a snapshot every 2 generations (checkpoints only at the end)."""
    logdir = tmp_path_factory.mktemp("parent")
    return new_run(logdir, "--generations", 6, "--snapshot-every", 2, "--checkpoint-every", 100)


def test_snapshots_are_checkpoints_of_their_generation(parent):
    snaps = sorted(p.name for p in (parent / "snapshots").iterdir())
    assert snaps == ["generation-000002.pt", "generation-000004.pt", "generation-000006.pt"]
    for g in (2, 4, 6):
        d = read_checkpoint(parent / "snapshots" / f"generation-{g:06d}.pt")
        assert d["generation"] == g and len(d["history"]) == g
    # the latest checkpoint stays where it was, and is the last snapshot's state
    assert same_state(
        read_checkpoint(parent / "checkpoint.pt"),
        read_checkpoint(parent / "snapshots" / "generation-000006.pt"),
    )


def test_branch_without_changes_continues_as_the_parent(parent, tmp_path):
    """A branch of generation 2 with the parent's settings computes generations 2-5 exactly as
    the parent did; it records its parent in config.toml, summary.json and inspect."""
    child = new_run(tmp_path, "--from", f"{parent}@2")
    assert child.parent == tmp_path
    assert sorted(rows(child)) == [2, 3, 4, 5]
    assert rows(child) == {g: r for g, r in rows(parent).items() if g >= 2}
    assert teams(child) == {g: t for g, t in teams(parent).items() if g >= 2}
    assert same_state(
        read_checkpoint(child / "checkpoint.pt"), read_checkpoint(parent / "checkpoint.pt")
    )
    want = {
        "run": str(parent.absolute()),
        "generation": 2,
        "checkpoint": "snapshots/generation-000002.pt",
    }
    assert config_toml(child)["parent"] == want
    assert json.loads((child / "summary.json").read_text())["parent"] == want
    assert (child / "scenario.toml").read_bytes() == (parent / "scenario.toml").read_bytes()
    assert (child / "hardware.toml").read_bytes() == (parent / "hardware.toml").read_bytes()
    r = invoke("inspect", child)
    assert r.exit_code == 0 and f"Branched from {parent.absolute()} at generation 2" in r.output
    # resuming the branch keeps it a branch
    r = invoke("evolve", "--resume", child, "--generations", 7)
    assert r.exit_code == 0, r.output
    assert config_toml(child)["parent"] == want


def test_branch_with_set_changes_exactly_that_setting(parent, tmp_path):
    seen = []

    class First:
        def on_start(self, ev):
            from swarmcode_torch.app.run_record import app_record

            # the algorithm's state and the application's record, as a checkpoint holds them
            seen.append({**ev.state_dict(), "app": app_record(ev).state_dict()})

        def on_generation(self, ev, result):
            pass

        def on_end(self, ev):
            pass

    res = sc.evolve(
        from_run=f"{parent}@4", logdir=tmp_path, generations=6, delta=0.55, reporters=[First()]
    )
    a, b = config_toml(parent), config_toml(res.run_dir)
    assert b.pop("parent")["generation"] == 4
    assert {k for k in a if a[k] != b.get(k)} | {k for k in b if b[k] != a.get(k)} == {"delta"}
    assert b["delta"] == 0.55
    # the branch's first state is the parent's snapshot, under the new config
    snap = read_checkpoint(parent / "snapshots" / "generation-000004.pt")
    assert same_state(seen[0], snap)
    assert seen[0]["config"]["delta"] == 0.55
    assert res.generations == 6 and [h["generation"] for h in res.history] == [4, 5]


def test_branch_with_another_seed_restarts_the_generator(parent, tmp_path):
    seen = []

    class First:
        def on_start(self, ev):
            seen.append(ev.state.rng_state.clone())

        def on_generation(self, ev, result):
            pass

        def on_end(self, ev):
            pass

    sc.evolve(from_run=f"{parent}@4", logdir=None, generations=5, seed=11, reporters=[First()])
    snap = read_checkpoint(parent / "snapshots" / "generation-000004.pt")
    assert not torch.equal(seen[0], snap["rng_state"])
    assert torch.equal(seen[0], torch.Generator().manual_seed(11).get_state())


def test_branch_errors_are_one_line(parent, tmp_path):
    r = invoke("evolve", "--from", tmp_path / "nothing")
    assert_clean_error(r, "is not a run directory")
    r = invoke("evolve", "--from", f"{parent}@3")
    assert_clean_error(r, "no snapshot of generation 3", "snapshots of generations: 2, 4, 6")
    r = invoke("evolve", "--from", f"{parent}@x1")
    assert_clean_error(r, "is not a run directory")
    r = invoke("evolve", "--from", f"{parent}@-1")
    assert_clean_error(r, "must be an integer >= 0")
    for option, value, key in (
        ("--population", 8, "--population"),
        ("--scenario", "two-niche", "--scenario"),
        ("--set", "tag_length=8", "--set tag_length"),
    ):
        r = invoke("evolve", "--from", f"{parent}@2", option, value, "--logdir", tmp_path)
        assert_clean_error(r, f"{key} cannot change when branching")
    r = invoke("evolve", "--from", f"{parent}@4", "--generations", 4, "--logdir", tmp_path)
    assert_clean_error(r, "must be more than the snapshot's 4 generations")
    r = invoke("evolve", "--from", parent, "--resume", parent)
    assert_clean_error(r, "--resume uses the run's saved config", "--from")
    assert list(tmp_path.iterdir()) == []  # no run directory made by any of them


def test_branch_refuses_linked_and_corrupt_snapshots(parent, tmp_path):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(parent, run)
    snap = run / "snapshots" / "generation-000002.pt"
    snap.write_bytes(snap.read_bytes()[:500])  # cut short
    r = invoke("evolve", "--from", f"{run}@2", "--logdir", tmp_path / "out")
    assert_clean_error(r, "is corrupt or not a checkpoint")
    snap.unlink()
    snap.symlink_to(parent / "snapshots" / "generation-000002.pt")
    r = invoke("evolve", "--from", f"{run}@2", "--logdir", tmp_path / "out")
    assert_clean_error(r, "symbolic link")
    shutil.rmtree(run / "snapshots")
    (run / "snapshots").symlink_to(parent / "snapshots")
    r = invoke("evolve", "--from", f"{run}@2", "--logdir", tmp_path / "out")
    assert_clean_error(r, "snapshots is a symbolic link")
    assert not (tmp_path / "out").exists()


def test_parse_run_ref():
    assert parse_run_ref("runs/a") == (Path("runs/a"), None)
    assert parse_run_ref("runs/a@100") == (Path("runs/a"), 100)
    assert parse_run_ref("runs/me@home/a") == (Path("runs/me@home/a"), None)
    with pytest.raises(ValueError, match="integer >= 0"):
        parse_run_ref("runs/a@")


# ------------------------------------------------------------------ bounds
class FakeClock:
    """session.clock: 10 seconds more at every reading."""

    def __init__(self):
        self.t = 0.0

    def __call__(self):
        self.t += 10.0
        return self.t


def test_max_time_stops_cleanly_and_resume_continues_identically(monkeypatch, tmp_path):
    monkeypatch.setattr(session, "clock", FakeClock())
    run = tmp_path / "a"
    # read at the start (10), then after each generation (20, 30, 40): 30 s past the start
    # is reached after the third generation
    stopped = new_run(run, "--generations", 6, "--max-time", "30s")
    r_out = json.loads((stopped / "summary.json").read_text())
    assert r_out["stop"] == {
        "reason": "max_time",
        "generation": 3,
        "max_time_seconds": 30.0,
        "elapsed_seconds": 30.0,
    }
    assert read_checkpoint(stopped / "checkpoint.pt")["generation"] == 3
    assert sorted(rows(stopped)) == [0, 1, 2]
    monkeypatch.setattr(session, "clock", FakeClock())
    r = invoke("evolve", "--resume", stopped)
    assert r.exit_code == 0, r.output
    straight = new_run(tmp_path / "b", "--generations", 6)
    assert rows(stopped) == rows(straight)
    assert teams(stopped) == teams(straight)
    assert same_state(
        read_checkpoint(stopped / "checkpoint.pt"), read_checkpoint(straight / "checkpoint.pt")
    )
    assert json.loads((stopped / "summary.json").read_text())["stop"]["reason"] == "generations"


def test_max_time_message_and_exit(monkeypatch, tmp_path):
    monkeypatch.setattr(session, "clock", FakeClock())
    r = invoke("evolve", *TINY, "--generations", 5, "--max-time", "0.5m", "--logdir", tmp_path)
    assert r.exit_code == 0, r.output
    (run,) = tmp_path.iterdir()
    assert (
        f"Stopped after 3 generations (0-2): --max-time reached (30.0s of 30s); its checkpoint "
        f"is in {run}; continue with: swarmcode-torch evolve --resume {run}"
        in " ".join(r.output.split())
    )


def test_patience_stops_when_the_best_team_stalls(tmp_path):
    res = sc.evolve(logdir=tmp_path, generations=40, patience=2, **API_TINY)
    assert res.stopped == "patience"
    s = json.loads((res.run_dir / "summary.json").read_text())
    stop = s["stop"]
    assert stop["reason"] == "patience" and stop["patience"] == 2
    last = res.generations - 1
    assert stop["generation"] == res.generations < 40
    assert last - stop["best_generation"] == 2 == last - res.best_team["generation"]
    # no earlier generation had gone 2 generations without a better best team
    team = {g: json.loads(t)["fitness"] for g, t in teams(res.run_dir).items()}
    assert sorted(team) == list(range(last + 1))
    found = 0  # where the run's best team was found
    for g in range(1, last + 1):
        if team[g] > team[found]:
            found = g
        assert g - found < 2 or g == last, g  # no earlier stall of 2 generations
    assert found == stop["best_generation"]
    assert read_checkpoint(res.run_dir / "checkpoint.pt")["generation"] == res.generations


def test_bounds_are_checked():
    assert session.parse_duration("90m") == 5400
    assert session.parse_duration("2h") == 7200
    assert session.parse_duration("3600") == 3600
    assert session.parse_duration("1h30m") == 5400
    assert session.parse_duration(12.5) == 12.5
    for bad in ("", "1x", "-5", "0", "h", "10 20"):
        with pytest.raises(ValueError, match="max_time"):
            session.parse_duration(bad)
    with pytest.raises(ValueError, match="patience"):
        sc.evolve(logdir=None, patience=0, **API_TINY)
    assert_clean_error(invoke("evolve", "--max-time", "soon"), "--max-time must be a duration")
    assert_clean_error(invoke("evolve", "--patience", "0"), "--patience must be >= 1")
    assert_clean_error(invoke("evolve", "--snapshot-every", "-1"), "--snapshot-every")


def test_api_max_time_with_resume(monkeypatch, tmp_path):
    monkeypatch.setattr(session, "clock", FakeClock())
    res = sc.evolve(logdir=tmp_path, generations=5, max_time=20, snapshot_every=1, **API_TINY)
    assert res.stopped == "max_time" and res.generations == 2
    assert sorted(p.name for p in (res.run_dir / "snapshots").iterdir()) == [
        "generation-000001.pt",
        "generation-000002.pt",
    ]
    more = sc.resume(res.run_dir)
    assert more.stopped is None and more.generations == 5


# ------------------------------------------------------------------ config files
def test_print_config_of_a_runs_own_config_reads_back_the_same(parent, tmp_path):
    r = invoke("evolve", "--config", parent / "config.toml", "--print-config")
    assert r.exit_code == 0, r.output
    printed = tomllib.loads(r.output)
    assert printed == config_toml(parent)
    r = invoke(
        "evolve",
        "--config",
        parent / "config.toml",
        "--population",
        9,
        "--set",
        "delta=0.7",
        "--print-config",
    )
    changed = tomllib.loads(r.output)
    assert {k for k in printed if printed[k] != changed[k]} == {"population", "delta"}
    assert changed["population"] == 9 and changed["delta"] == 0.7
    assert list(tmp_path.iterdir()) == []


def test_print_config_defaults_and_branch():
    r = invoke("evolve", "--print-config")
    assert r.exit_code == 0, r.output
    d = tomllib.loads(r.output)
    assert SwarmCoDeConfig.from_dict(d) == SwarmCoDeConfig()


def test_config_file_starts_a_run(tmp_path):
    cfg = tmp_path / "run.toml"
    cfg.write_text(
        'scenario = "one-niche"\npopulation = 6\nswarm_size = 4\ntrials = 1\n'
        'ticks = 15\ngenerations = 2\ndelta = 0.6\ndevice = "cpu"\ncompile = false\n'
    )
    r = invoke(
        "evolve",
        "--config",
        cfg,
        "--generations",
        3,
        "--logdir",
        tmp_path / "runs",
        "--render-every",
        0,
    )
    assert r.exit_code == 0, r.output
    (run,) = (tmp_path / "runs").iterdir()
    got = config_toml(run)
    assert (got["population"], got["delta"], got["generations"], got["swarm_size"]) == (
        6,
        0.6,
        3,
        4,
    )
    res = sc.evolve(config=cfg, logdir=None, generations=1)
    assert res.config.delta == 0.6 and res.config.population == 6


def test_config_file_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("population = 8\nspeed = 3\n")
    assert_clean_error(invoke("evolve", "--config", bad), "unknown key 'speed'")
    bad.write_text("population = \n")
    assert_clean_error(invoke("evolve", "--config", bad), "malformed config")
    bad.write_text('population = "many"\n')
    assert_clean_error(invoke("evolve", "--config", bad, "--print-config"), "population")
    assert_clean_error(invoke("evolve", "--config", tmp_path / "none.toml"), "no such config")
    link = tmp_path / "link.toml"
    link.symlink_to(bad)
    assert_clean_error(invoke("evolve", "--config", link), "symbolic link")
    ok = tmp_path / "ok.toml"
    ok.write_text("population = 8\n")
    assert_clean_error(
        invoke("evolve", "--config", ok, "--from", tmp_path),
        "--config and --from cannot be used together",
    )
