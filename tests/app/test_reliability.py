"""Reliability (docs/RELIABILITY.md lists each promise with its test): a run is self-contained,
every value is checked before anything is made, messages, a bit-exact resume. The other
promises are tested by module: test_checkpoints.py, test_files.py, test_locks.py, test_sweep.py."""

import errno
import json
import os
from pathlib import Path

import pytest
import torch
from runkit import (
    FAST,
    MINE,
    RFAST,
    TINY,
    _copy_run,
    _full_disk_line,
    _scenario,
    invoke,
    one_line_error,
    tiny_run,
)

from swarmcode_torch.app import runconfig as runconfig_module
from swarmcode_torch.app import runs as runs_module
from swarmcode_torch.app.runs import load_checkpoint


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    return tiny_run(tmp_path_factory)


# ====================================================================== a run is self-contained
def test_a_run_keeps_its_scenario_and_resumes_and_replays_it_from_anywhere(tmp_path, monkeypatch):
    from swarmcode_torch.app.runs import hardware_bytes
    from swarmcode_torch.app.runs import resume as resume_run

    work, elsewhere = tmp_path / "work", tmp_path / "elsewhere"
    work.mkdir()
    elsewhere.mkdir()
    (work / "mine.toml").write_text(MINE)
    monkeypatch.chdir(work)
    r = invoke(
        "evolve",
        "--scenario",
        "mine.toml",
        "--population",
        6,
        "--trials",
        1,
        "--generations",
        2,
        *FAST,
        "--logdir",
        "runs",
    )
    assert r.exit_code == 0, r.output
    (run,) = [p.resolve() for p in (work / "runs").iterdir()]
    assert (run / "scenario.toml").read_text() == MINE
    assert (run / "hardware.toml").read_bytes() == hardware_bytes()
    assert 'scenario = "mine.toml"' in (run / "config.toml").read_text()
    # the original changes into another valid world, then goes away; we work from elsewhere
    (work / "mine.toml").write_text(MINE.replace("arena = 14.0", "arena = 30.0"))
    monkeypatch.chdir(elsewhere)
    ev = resume_run(run, generations=3)
    assert ev.ctx.scenario.arena == 14.0 and ev.cfg.scenario == "mine.toml"
    (work / "mine.toml").unlink()
    r = invoke("evolve", "--resume", run, "--generations", 3, *RFAST)
    assert r.exit_code == 0, r.output
    assert load_checkpoint(run)["config"]["scenario"] == "mine.toml"
    assert json.loads((run / "summary.json").read_text())["scenario"] == "mine.toml"
    r = invoke("replay", run, "--ticks", 4, "--out", elsewhere / "t.gif")
    assert r.exit_code == 0, r.output
    assert (elsewhere / "t.gif").is_file()
    r = invoke("inspect", run)
    assert r.exit_code == 0 and "lifts:" in r.output, r.output


def test_a_run_made_before_runs_kept_copies_still_resumes_and_replays(finished_run, tmp_path):
    run = _copy_run(finished_run, tmp_path / "run")
    (run / "scenario.toml").unlink()
    (run / "hardware.toml").unlink()
    # such a run's checkpoint has no digests of its copies ("run_files"); with them, a copy
    # that went missing is refused (test_an_edited_or_missing_copy_is_refused_on_resume)
    d = torch.load(run / "checkpoint.pt", weights_only=True)
    del d["run_files"]
    torch.save(d, run / "checkpoint.pt")
    r = invoke("evolve", "--resume", run, "--generations", 3, *RFAST)
    assert r.exit_code == 0, r.output
    assert not (run / "scenario.toml").exists()  # no copy made up after the fact
    r = invoke("replay", run, "--ticks", 4, "--out", tmp_path / "t.gif")
    assert r.exit_code == 0, r.output


def test_a_run_whose_catalog_differs_from_the_installed_one_resumes_with_its_own(
    finished_run, tmp_path
):
    from swarmcode_torch.app.runs import resume as resume_run

    run = _copy_run(finished_run, tmp_path / "run")
    text = (run / "hardware.toml").read_text()
    import re

    changed = re.sub(
        r"(?m)^(\s*mass\s*=\s*)([0-9.]+)", lambda m: m.group(1) + "9.75", text, count=1
    )
    assert changed != text
    (run / "hardware.toml").write_text(changed)  # as if the installed catalog had changed
    d = torch.load(run / "checkpoint.pt", weights_only=True)  # since the run started with it
    d["run_files"] = runs_module.copy_digests(run)
    torch.save(d, run / "checkpoint.pt")
    assert resume_run(run, generations=3).ctx.scenario.hardware.base_mass == 9.75
    r = invoke("evolve", "--resume", run, "--generations", 3, *RFAST)
    assert r.exit_code == 0, r.output
    r = invoke("replay", run, "--ticks", 4, "--out", tmp_path / "t.gif")
    assert r.exit_code == 0, r.output


def test_a_config_toml_that_differs_from_the_checkpoint_names_the_keys(finished_run, tmp_path):
    run = _copy_run(finished_run, tmp_path / "run")
    good = (run / "config.toml").read_text()
    (run / "config.toml").write_text(
        good.replace("seed = 3", "seed = 4").replace("delta = 0.4", "delta = 0.5")
    )
    one_line_error(
        invoke("evolve", "--resume", run, "--generations", 3, *RFAST),
        "does not match",
        "differing keys: delta, seed",
    )
    (run / "config.toml").write_text(good.replace("generations = 2", "generations = 3"))
    r = invoke("evolve", "--resume", run, *RFAST)  # generations may differ
    assert r.exit_code == 0, r.output


def _snapshot(run: Path) -> dict:
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in run.iterdir()}


@pytest.mark.parametrize("asked", [None, 1, 2])
def test_resume_to_no_more_generations_changes_nothing(finished_run, tmp_path, asked):
    run = _copy_run(finished_run, tmp_path / "run")
    before = _snapshot(run)
    r = invoke("evolve", "--resume", run, *([] if asked is None else ["--generations", asked]))
    assert r.exit_code == 0, r.output
    assert "already has 2 generations" in r.output and "nothing to do" in r.output
    assert _snapshot(run) == before  # no file written, none added


def test_logdir_with_resume_is_refused(finished_run, tmp_path):
    one_line_error(
        invoke("evolve", "--resume", finished_run, "--logdir", tmp_path),
        "--logdir cannot be used with --resume",
    )


# ====================================================================== every value is checked
@pytest.mark.parametrize(
    "args,needles",
    [
        (["--budget", "nan"], ["--budget must be a finite number"]),
        (["--budget", "inf"], ["--budget must be a finite number"]),
        (["--budget", "-inf"], ["--budget must be a finite number"]),
        (["--seed", str(2**63)], ["--seed must be in [0, 9223372036854775807]"]),
        (["--seed", "-1"], ["--seed must be >= 0"]),
        (["--population", "1000000000000"], ["would need about", "PiB", "--population"]),
        (["--set", "bt_length=100000000000"], ["would need about", "TiB"]),
        (["--set", "bt_length=100000"], ["--set bt_length must be <= 4096"]),
        (["--set", "tag_length=0"], ["--set tag_length must be >= 1"]),
        (["--set", "alpha=1.5"], ["--set alpha must be <= 1"]),
        (["--set", "p_marginal=-0.1"], ["--set p_marginal must be a finite number in [0, 1]"]),
        (["--set", "delta=0"], ["--set delta must be a finite number > 0"]),
        (["--set", "lam=inf"], ["--set lam must be a finite number >= 0"]),
        (["--set", "hw_sigma=nan"], ["--set hw_sigma must be a finite number >= 0"]),
        (["--set", "min_share=-1"], ["--set min_share must be a finite number >= 0"]),
        (["--set", "p_gene_mutation=2"], ["--set p_gene_mutation must be <= 1"]),
        (["--set", "delta=0.5", "--set", "delta=0.6"], ["--set delta is given twice"]),
        (["--generations", "1000000000"], ["--generations must be <= 10000000"]),
        (["--ticks", "1000000000"], ["--ticks must be <= 1000000"]),
        (["--trials", "100000000000"], ["would need about", "--trials"]),
        (["--device", "cuda:x"], ["--device must be auto, cpu, cuda or cuda:N"]),
    ],
)
def test_options_and_set_values_are_checked_before_anything_is_made(tmp_path, args, needles):
    one_line_error(invoke("evolve", "--logdir", tmp_path / "runs", *args), *needles)
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize(
    "change,needles",
    [
        (("mass = [1.0, 3.0]", "mass = [nan, 3.0]"), ["packages[0].mass", "finite"]),
        (("distance = [2.5, 5.0]", "distance = [2.5, nan]"), ["packages[0].distance", "finite"]),
        (("arena = 14.0", "arena = inf"), ["arena: expected a finite number"]),
        (("arena = 14.0", "arena = 20000.0"), ["arena: must be in (0, 10000] m"]),
        (
            ("distance = [2.5, 5.0]", "distance = [2.5, 30.0]"),
            ["packages[0].distance", "outside the arena"],
        ),
        (
            ("distance = [2.5, 5.0]", "distance = [8.0, 9.0]"),
            ["packages[0].distance", "outside the arena in most directions"],
        ),
        (
            ("distance = [2.5, 5.0]", "distance = [0.5, 5.0]"),
            ["packages[0].distance", "inside the base"],
        ),
        (("count = 3", "count = 400"), ["packages[0].count", "do not fit"]),
        (
            ("mass = [1.0, 3.0]", "mass = [1.0, 3.0]\nradius_band = [0.6, 0.9]"),
            ["packages[0].radius_band", "no robot radius", "0.15-0.5"],
        ),
        (
            (
                "episode_ticks = 10",
                "episode_ticks = 10\n[obstacles]\ncount = 100\nradius = [1.0, 1.5]",
            ),
            ["obstacles", "more than half"],
        ),
        (
            (
                "episode_ticks = 10",
                "episode_ticks = 10\n[obstacles]\ncount = 1\nradius = [7.0, 7.5]",
            ),
            ["obstacles.radius", "does not fit"],
        ),
        (
            ("distance = [2.5, 5.0]", 'distance = "far"'),
            ["packages[0].distance: expected [low, high], got 'far'"],
        ),
        (
            ("num_robots = 4", "num_robots = 10000000000"),
            ["would need about", "10000000000 robots"],
        ),
        (("num_robots = 4", "num_robots = 4.5"), ["num_robots: expected int"]),
        (("[[packages]]", "[[packagez]]"), ["packagez: unknown field"]),
    ],
)
def test_a_scenario_file_is_checked_field_by_field(tmp_path, change, needles):
    path = _scenario(tmp_path, MINE.replace(*change))
    assert MINE.replace(*change) != MINE
    r = invoke(
        "evolve",
        "--scenario",
        path,
        "--population",
        6,
        "--trials",
        1,
        "--logdir",
        tmp_path / "runs",
    )
    one_line_error(r, str(path), *needles)
    assert not (tmp_path / "runs").exists()


def test_a_scenario_without_packages_keeps_its_brackets_in_the_message(tmp_path):
    path = _scenario(tmp_path, MINE[: MINE.index("[[packages]]")])
    one_line_error(
        invoke("evolve", "--scenario", path, "--logdir", tmp_path / "runs"),
        "expected at least one [[packages]] table",
    )


def test_a_scenario_with_a_byte_order_mark_is_read(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + MINE.encode())
    r = invoke(
        "evolve",
        "--scenario",
        path,
        "--population",
        4,
        "--trials",
        1,
        "--ticks",
        5,
        "--generations",
        1,
        *FAST,
        "--logdir",
        tmp_path / "runs",
    )
    assert r.exit_code == 0, r.output
    (run,) = list((tmp_path / "runs").iterdir())
    assert (run / "scenario.toml").read_bytes() == path.read_bytes()  # kept as read


def test_undecodable_run_files_and_scenarios_name_the_file(finished_run, tmp_path):
    bad = _scenario(tmp_path, "")
    bad.write_bytes(b'name = "\xff\xfe"\n')
    one_line_error(
        invoke("evolve", "--scenario", bad, "--logdir", tmp_path / "runs"), str(bad), "not UTF-8"
    )
    for name, command in (
        ("config.toml", ["evolve", "--resume", "RUN", "--generations", 3]),
        ("summary.json", ["inspect", "RUN"]),
        ("teams.jsonl", ["replay", "RUN", "--generation", 1]),
    ):
        run = _copy_run(finished_run, tmp_path / f"run-{name}")
        (run / name).write_bytes((run / name).read_bytes() + b"\xc3\x28 \xff\n")
        one_line_error(
            invoke(*[run if a == "RUN" else a for a in command]), str(run / name), "not UTF-8"
        )


@pytest.mark.parametrize(
    "name,edit,command,needles",
    [
        (
            "config.toml",
            ("population = 6", "population = 6.5"),
            "resume",
            ["population must be an integer"],
        ),
        (
            "config.toml",
            ("delta = 0.4", "delta = nan"),
            "replay",
            ["config.toml", "delta must be a finite number"],
        ),
        ("config.toml", ("seed = 3", "seed = -3"), "replay", ["seed must be >= 0"]),
        (
            "config.toml",
            ("population = 6", "population = [6]"),
            "resume",
            ["population: expected a single value"],
        ),
        (
            "summary.json",
            ('"radius": ', '"radius": "big", "x": '),
            "inspect",
            ["designs[0].radius", "big"],
        ),
        (
            "summary.json",
            ('"best_fitness": ', '"best_fitness": "high", "x": '),
            "inspect",
            ["best_fitness: expected a number"],
        ),
        (
            "summary.json",
            ('"designs": [', '"designs": [7, '),
            "replay",
            ["designs[0]: expected a table"],
        ),
        (
            "teams.jsonl",
            ('"chassis_tier": ', '"chassis_tier": 9, "x": '),
            "replay1",
            ["generation 1", "designs[0].chassis_tier"],
        ),
    ],
)
def test_run_files_read_back_are_checked(finished_run, tmp_path, name, edit, command, needles):
    run = _copy_run(finished_run, tmp_path / "run")
    text = (run / name).read_text()
    assert edit[0] in text
    (run / name).write_text(text.replace(edit[0], edit[1]))
    args = {
        "resume": ["evolve", "--resume", run, "--generations", 3],
        "replay": ["replay", run, "--out", tmp_path / "t.gif"],
        "replay1": ["replay", run, "--generation", 1, "--out", tmp_path / "t.gif"],
        "inspect": ["inspect", run],
    }[command]
    one_line_error(invoke(*args), str(run / name), *needles)


# ====================================================================== messages
def test_error_messages_keep_brackets_and_name_the_option(tmp_path):
    path = _scenario(tmp_path, MINE.replace("mass = [1.0, 3.0]", "mass = [3.0]"))
    r = invoke("evolve", "--scenario", path, "--logdir", tmp_path / "runs")
    one_line_error(r, "packages[0].mass: expected [low, high], got [3.0]")
    one_line_error(
        invoke("evolve", "--seed", str(2**64), "--logdir", tmp_path / "runs"), "--seed must be in"
    )
    one_line_error(invoke("replay", tmp_path, "--seed", str(2**64)), "--seed must be in")


# ====================================================================== bit-exact resume
def test_a_resumed_run_writes_the_same_records_as_one_straight_through(tmp_path):
    straight, parts = tmp_path / "straight", tmp_path / "parts"
    args = [*TINY, *FAST, "--checkpoint-every", 1]
    assert invoke("evolve", *args, "--generations", 4, "--logdir", straight).exit_code == 0
    assert invoke("evolve", *args, "--generations", 2, "--logdir", parts).exit_code == 0
    (a,), (b,) = list(straight.iterdir()), list(parts.iterdir())
    r = invoke("evolve", "--resume", b, "--generations", 4, *RFAST)
    assert r.exit_code == 0, r.output
    assert (a / "teams.jsonl").read_bytes() == (b / "teams.jsonl").read_bytes()
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (a, b))
    for s in (sa, sb):
        s["last_generation"] = {
            k: v for k, v in s["last_generation"].items() if not k.startswith("perf/")
        }  # timings
    assert sa == sb
    ca, cb = load_checkpoint(a), load_checkpoint(b)
    assert torch.equal(ca["rng_state"], cb["rng_state"]) and ca["history"] == cb["history"]
    assert all(torch.equal(ca["genome"][k], cb["genome"][k]) for k in ca["genome"])


def test_a_run_stopped_before_its_first_periodic_checkpoint_resumes_from_generation_0(
    tmp_path, monkeypatch
):
    from swarmcode_torch.coevo.evolve import Evolution

    def full(self):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Evolution, "step", full)
    r = invoke(
        "evolve", *TINY, "--generations", 2, "--checkpoint-every", 100, *FAST, "--logdir", tmp_path
    )
    monkeypatch.undo()
    (run,) = list(tmp_path.iterdir())
    _full_disk_line(r, run, 0)
    r = invoke("evolve", "--resume", run, *RFAST)
    assert r.exit_code == 0, r.output
    assert load_checkpoint(run)["generation"] == 2


def test_usage_errors_are_one_line(tmp_path):
    one_line_error(invoke("evolve", "--population", "abc"), "Invalid value for '--population'")
    one_line_error(invoke("evolve", "--no-such-option"), "No such option: --no-such-option")
    one_line_error(invoke("replay"), "Missing argument")


def test_a_run_too_big_for_this_machine_replays_and_inspects_but_does_not_resume(
    finished_run, tmp_path, monkeypatch
):
    run = _copy_run(finished_run, tmp_path / "run")
    monkeypatch.setattr(runconfig_module, "memory_limit", lambda device="auto": (1024, "memory"))
    r = invoke("replay", run, "--ticks", 4, "--out", tmp_path / "t.gif")
    assert r.exit_code == 0, r.output
    assert invoke("inspect", run).exit_code == 0
    one_line_error(
        invoke("evolve", "--resume", run, "--generations", 3, *RFAST),
        "would need about",
        "more than the 1 KiB of memory",
    )
