"""Hostile inputs (issue 29): links planted in a run directory, catalog paths leading out of a
scenario's folder, oversized and deeply nested files, checkpoints whose tensors do not fit their
config, damaged CSV and JSON, unreachable Ray addresses, and the silent wrongs (empty paths,
edited copies, empty configs, renamed headers, unknown opcodes, huge user scores, in-place
edits, API arguments). Each case: a one-line error and exit 2 (or an exception from the API)
before anything is written, never a traceback, and nothing outside the run touched.
docs/RELIABILITY.md lists each promise with its test here."""

from __future__ import annotations

import io
import json
import os
import time
from pathlib import Path

import pytest
import torch
from hostilekit import RFAST, TINY, _snapshot, invoke, one_line_error, tiny_run
from runkit import _copy_run  # the same copy of a run directory


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    return tiny_run(tmp_path_factory)


# ====================================================================== links and paths
@pytest.mark.parametrize(
    "name",
    [
        "run.lock",
        "teams.jsonl",
        "metrics.csv",
        "checkpoint.pt",
        "summary.json",
        "config.toml",
        "scenario.toml",
        "hardware.toml",
        "teams.jsonl.partial",
    ],
)
def test_links_planted_in_a_run_directory_are_never_followed(finished_run, tmp_path, name):
    run = _copy_run(finished_run, tmp_path / "run")
    outside = tmp_path / f"outside-{name}"
    real = run / name
    outside.write_bytes(real.read_bytes() if real.exists() else b"precious\n")
    before = outside.read_bytes()
    real.unlink(missing_ok=True)
    real.symlink_to(outside)
    r = invoke("evolve", "--resume", run, "--generations", 3, *RFAST)
    one_line_error(r, str(real), "symbolic link")
    assert outside.read_bytes() == before  # not truncated, appended or replaced
    assert real.is_symlink()


def test_run_files_open_without_following_links(tmp_path):
    from swarmcode_torch.app import runs

    target = tmp_path / "target"
    target.write_bytes(b"keep\n")
    (tmp_path / "teams.jsonl").symlink_to(target)
    with pytest.raises(OSError, match="symbolic link"):
        runs.append_line(tmp_path / "teams.jsonl", "{}")
    with pytest.raises(OSError, match="symbolic link"):
        runs.repair_teams(tmp_path)
    with pytest.raises(runs.RunError, match="symbolic link"):
        runs.read_text(tmp_path / "teams.jsonl")
    (tmp_path / "run.lock").symlink_to(target)
    with pytest.raises(runs.RunError, match="symbolic link"):
        runs.RunLock(tmp_path).acquire()
    assert target.read_bytes() == b"keep\n"


def test_replay_refuses_a_planted_team_gif_link_and_never_writes_through_it(finished_run, tmp_path):
    run = _copy_run(finished_run, tmp_path / "run")
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    (run / "team.gif").symlink_to(victim)
    r = invoke("replay", run, "--ticks", 4)
    assert r.exit_code != 0 and "symbolic link" in r.output and "Traceback" not in r.output
    assert victim.read_text() == "precious" and (run / "team.gif").is_symlink()


SCEN = """name = "mine"
arena = 14.0
base_radius = 1.5
num_robots = 4
episode_ticks = 10
{hardware}
[[packages]]
kind = "individual"
effector = "suction"
count = 2
distance = [3.0, 5.0]
mass = [1.0, 2.0]
"""


@pytest.mark.parametrize(
    "where", ["/etc/passwd", "/proc/self/environ", "../outside.toml", "link.toml"]
)
def test_a_scenarios_catalog_path_must_stay_in_its_folder(tmp_path, where):
    from swarmcode_torch.sim.hardware import default_catalog_bytes

    folder = tmp_path / "scen"
    folder.mkdir()
    (tmp_path / "outside.toml").write_bytes(default_catalog_bytes())  # a valid catalog
    (folder / "link.toml").symlink_to(tmp_path / "outside.toml")
    (folder / "s.toml").write_text(SCEN.format(hardware=f'hardware = "{where}"'))
    r = invoke("evolve", "--scenario", folder / "s.toml", "--logdir", tmp_path / "runs")
    one_line_error(r, "outside the scenario's folder")
    assert not (tmp_path / "runs").exists()


def test_a_catalog_beside_the_scenario_is_still_read(tmp_path):
    from swarmcode_torch.sim.hardware import default_catalog_bytes
    from swarmcode_torch.sim.scenario import load_scenario

    (tmp_path / "hw.toml").write_bytes(default_catalog_bytes())
    (tmp_path / "s.toml").write_text(SCEN.format(hardware='hardware = "hw.toml"'))
    assert load_scenario(str(tmp_path / "s.toml")).name == "mine"


@pytest.mark.parametrize("which", ["scenario", "catalog"])
def test_oversized_scenario_and_catalog_files_are_refused_unread(tmp_path, which):
    big = tmp_path / ("s.toml" if which == "scenario" else "hw.toml")
    with open(big, "wb") as f:  # a sparse 1 GiB file: reading it whole would hang
        f.truncate(2**30)
    if which == "catalog":
        (tmp_path / "s.toml").write_text(SCEN.format(hardware='hardware = "hw.toml"'))
    t = time.monotonic()
    r = invoke("evolve", "--scenario", tmp_path / "s.toml", "--logdir", tmp_path / "runs")
    one_line_error(r, "bytes, more than")
    assert time.monotonic() - t < 10


# ====================================================================== bounds
def test_a_megabyte_scenario_name_is_one_line_at_once(tmp_path):
    t = time.monotonic()
    one_line_error(
        invoke("evolve", "--scenario", "x" * 2**20, "--logdir", tmp_path / "r"),
        "scenario: a name or path of 1048576 characters",
    )
    (tmp_path / "s.toml").write_text(
        SCEN.format(hardware="").replace('"mine"', '"' + "n" * 2**20 + '"')
    )
    one_line_error(
        invoke("evolve", "--scenario", tmp_path / "s.toml", "--logdir", tmp_path / "r"),
        "name: expected 1 to 200 printable characters",
    )
    assert time.monotonic() - t < 20
    assert not (tmp_path / "r").exists()


DEEP_TOML = "x = " + "[" * 5000 + "]" * 5000 + "\n"
DEEP_JSON = "[" * 100_000 + "]" * 100_000


@pytest.mark.parametrize(
    "name", ["scenario", "config.toml", "hardware.toml", "summary.json", "teams.jsonl"]
)
def test_deeply_nested_toml_and_json_are_one_line(finished_run, tmp_path, name):
    if name == "scenario":
        (tmp_path / "s.toml").write_text(SCEN.format(hardware=DEEP_TOML))
        r = invoke("evolve", "--scenario", tmp_path / "s.toml", "--logdir", tmp_path / "r")
        one_line_error(r, "s.toml", "nested")
        return
    run = _copy_run(finished_run, tmp_path / "run")
    if name in ("config.toml", "hardware.toml"):
        with open(run / name, "a") as f:
            f.write(DEEP_TOML)
        r = invoke("replay", run, "--ticks", 2, "--out", tmp_path / "t.gif")
    elif name == "summary.json":
        (run / name).write_text(DEEP_JSON)
        r = invoke("inspect", run)
    else:
        with open(run / name, "a") as f:
            f.write(DEEP_JSON + "\n")
        r = invoke("replay", run, "--generation", 0, "--ticks", 2, "--out", tmp_path / "t.gif")
    one_line_error(r, name, "nested")


def test_the_memory_check_counts_the_start_slots_and_packages_are_bounded(tmp_path):
    from swarmcode_torch.app.runs import estimate_bytes
    from swarmcode_torch.coevo.config import SwarmCoDeConfig
    from swarmcode_torch.sim.scenario import load_scenario

    many = (
        SCEN.format(hardware="")
        .replace("num_robots = 4", "num_robots = 100000")
        .replace("arena = 14.0", "arena = 5000.0")
    )
    (tmp_path / "many.toml").write_text(many)
    scen = load_scenario(str(tmp_path / "many.toml"))
    cfg = SwarmCoDeConfig(scenario=str(tmp_path / "many.toml"), population=2, trials=1)
    assert estimate_bytes(cfg, scen) >= 3 * 8 * 100_000**2  # spawn_slots' cdist
    r = invoke(
        "evolve",
        "--scenario",
        tmp_path / "many.toml",
        "--population",
        2,
        "--trials",
        1,
        "--logdir",
        tmp_path / "r",
    )
    one_line_error(r, "would need about")
    pk = (
        SCEN.format(hardware="")
        .replace("count = 2", "count = 1000000")
        .replace("arena = 14.0", "arena = 10000.0")
        .replace("distance = [3.0, 5.0]", "distance = [3.0, 4000.0]")
    )
    (tmp_path / "pk.toml").write_text(pk)
    r = invoke("evolve", "--scenario", tmp_path / "pk.toml", "--logdir", tmp_path / "r")
    one_line_error(r, "packages: 1000000 packages, more than 10000")
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize(
    "count,needle", [(10**12, "more than any run can have"), (5_000_000, "would need about")]
)
def test_design_counts_are_bounded_before_replay_allocates(finished_run, tmp_path, count, needle):
    run = _copy_run(finished_run, tmp_path / "run")
    s = json.loads((run / "summary.json").read_text())
    s["designs"][0]["count"] = count
    (run / "summary.json").write_text(json.dumps(s))
    one_line_error(invoke("replay", run, "--ticks", 2, "--out", tmp_path / "t.gif"), needle)
    if count > 10**7:
        one_line_error(invoke("inspect", run), needle)


def _edit_checkpoint(run: Path, edit) -> None:
    d = torch.load(run / "checkpoint.pt", weights_only=True)
    edit(d)
    buf = io.BytesIO()
    torch.save(d, buf)
    (run / "checkpoint.pt").write_bytes(buf.getvalue())


def _set(key, value):
    def edit(d):
        d[key] = value

    return edit


def _genome(field, fn):
    def edit(d):
        d["genome"][field] = fn(d["genome"][field])

    return edit


@pytest.mark.parametrize(
    "edit,needle",
    [
        (_genome("radius", lambda t: t[:3]), "radius has shape"),
        (_genome("bt", lambda t: t.fill_(99)), "bt holds values outside 0..13"),
        (_genome("radius", lambda t: t.fill_(float("nan"))), "radius holds values outside"),
        (_genome("tag", lambda t: t.long()), "tag has dtype"),
        (_genome("effector", lambda t: t.fill_(7)), "effector holds values outside"),
        (_set("rng_state", torch.zeros(7, dtype=torch.uint8)), "another kind of device"),
        (_set("rng_state", torch.zeros(5056, dtype=torch.float32)), "rng_state has dtype"),
        (_set("fitness", torch.zeros(3)), "fitness has shape"),
        (_set("fitness", torch.full((6,), float("nan"))), "fitness holds NaN"),
        (_set("generation", -5), "generation must be an integer >= 0"),
        (_set("species_hint", torch.full((6,), 10**6)), "species_hint holds ids"),
        (_set("history", []), "history must hold one record per generation"),
    ],
)
def test_checkpoint_tensors_are_checked_against_the_config(finished_run, tmp_path, edit, needle):
    run = _copy_run(finished_run, tmp_path / "run")
    _edit_checkpoint(run, edit)
    before = _snapshot(run)
    one_line_error(
        invoke("evolve", "--resume", run, "--generations", 4, *RFAST), "checkpoint.pt", needle
    )
    assert _snapshot(run) == before  # nothing written


def _damage_row(text: str, row: int, change) -> str:
    lines = text.splitlines()
    assert len(lines) >= row + 3  # a row inside the file, not the last one
    lines[row + 1] = change(lines[row + 1])
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    "damage,needle",
    [
        (lambda t: t.replace("generation", "gen", 1), "not a metrics.csv header"),
        (lambda t: t.encode("utf-8")[:-1] + b"\xff\xfe\n", "is not UTF-8 text"),
        (lambda t: t + '"' + "x" * 200_000 + '"\n', "malformed CSV"),
        # rows inside the file that a resume used to drop silently (rows 0, 1 became 1)
        (lambda t: _damage_row(t, 0, lambda r: r + ",1.5"), "data row 1 is damaged (more cells"),
        (lambda t: _damage_row(t, 0, lambda r: "x" + r), "data row 1 is damaged (generation"),
        (
            lambda t: _damage_row(t, 0, lambda r: r.rsplit(",", 3)[0]),
            "data row 1 is damaged (fewer",
        ),
    ],
)
def test_a_damaged_metrics_csv_is_one_line_and_kept(finished_run, tmp_path, damage, needle):
    run = _copy_run(finished_run, tmp_path / "run")
    data = damage((run / "metrics.csv").read_text())
    (run / "metrics.csv").write_bytes(data if isinstance(data, bytes) else data.encode())
    before = _snapshot(run)
    one_line_error(
        invoke("evolve", "--resume", run, "--generations", 3, *RFAST), "metrics.csv", needle
    )
    assert _snapshot(run) == before  # its rows are not lost


def test_non_utf8_path_bytes_and_nul_in_paths_are_one_line(tmp_path):
    bad = os.fsdecode(bytes(tmp_path) + b"/caf\xe9")
    one_line_error(
        invoke("evolve", *TINY, "--generations", 1, "--logdir", bad), "--logdir", "not UTF-8"
    )
    one_line_error(invoke("inspect", bad), "RUN_DIR", "not UTF-8")


# ====================================================================== silent wrongs
def test_empty_logdir_and_out_are_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    one_line_error(invoke("evolve", *TINY, "--generations", 1, "--logdir", ""), "--logdir is empty")
    one_line_error(invoke("sweep", "--budgets", "1000", "--out", ""), "--out is empty")
    one_line_error(invoke("sweep", "--budgets", "1000", "--logdir", ""), "--logdir is empty")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("gens", [0, -5])
def test_resume_to_zero_or_negative_generations_is_refused(finished_run, tmp_path, gens):
    run = _copy_run(finished_run, tmp_path / "run")
    before = _snapshot(run)
    one_line_error(
        invoke("evolve", "--resume", run, "--generations", gens, *RFAST),
        "--generations must be >= 1",
    )
    assert _snapshot(run) == before


@pytest.mark.parametrize(
    "name,edit", [("scenario.toml", "edit"), ("hardware.toml", "edit"), ("scenario.toml", "delete")]
)
def test_an_edited_or_missing_copy_is_refused_on_resume(finished_run, tmp_path, name, edit):
    run = _copy_run(finished_run, tmp_path / "run")
    if edit == "delete":
        (run / name).unlink()
    else:
        with open(run / name, "a") as f:
            f.write("\n# edited\n")
    one_line_error(
        invoke("evolve", "--resume", run, "--generations", 3, *RFAST),
        name,
        "is missing" if edit == "delete" else "was changed",
    )


def test_an_empty_config_toml_is_refused_not_read_as_defaults(finished_run, tmp_path):
    run = _copy_run(finished_run, tmp_path / "run")
    (run / "config.toml").write_text("")
    one_line_error(
        invoke("replay", run, "--out", tmp_path / "t.gif"), "config.toml", "empty config"
    )
    one_line_error(invoke("evolve", "--resume", run, *RFAST), "config.toml", "empty config")


def test_inspect_refuses_unknown_opcodes(finished_run, tmp_path):
    run = _copy_run(finished_run, tmp_path / "run")
    s = json.loads((run / "summary.json").read_text())
    s["designs"][0]["bt"][0] = 200
    (run / "summary.json").write_text(json.dumps(s))
    one_line_error(invoke("inspect", run), "designs[0].bt", "opcodes 0..13")


def test_a_sweep_table_with_a_null_figure_is_written(tmp_path):
    from swarmcode_torch.app.sweep import markdown, table_rows

    out = tmp_path / "s"
    r = invoke(
        "sweep",
        "--budgets",
        "1000",
        "--generations",
        1,
        "--population",
        6,
        "--trials",
        1,
        "--ticks",
        5,
        "--device",
        "cpu",
        "--no-compile",
        "--out",
        out,
    )
    assert r.exit_code == 0, r.output
    (run,) = [d for d in out.iterdir() if d.is_dir()]
    s = json.loads((run / "summary.json").read_text())
    s["deliveries"] = None  # a figure that was not finite
    (run / "summary.json").write_text(json.dumps(s))
    rows = table_rows([(1000.0, 0, run)])
    assert rows[0]["deliveries"] is None and "none" in markdown(rows)
    r = invoke(
        "sweep",
        "--budgets",
        "1000",
        "--generations",
        1,
        "--population",
        6,
        "--trials",
        1,
        "--ticks",
        5,
        "--device",
        "cpu",
        "--no-compile",
        "--out",
        out,
    )
    assert r.exit_code == 0, r.output
