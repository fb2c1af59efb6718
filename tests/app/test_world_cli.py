"""`swarmcode-torch world`: writes a generated world as a scenario file (or prints it), the study
worlds by split and index, refuses to overwrite without --force and to write through a link,
and gives a one-line error for every bad option."""

from __future__ import annotations

import os

import pytest
from typer.testing import CliRunner

from swarmcode_torch.app.cli import app
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.worlds import (
    NEEDLE_SHARE,
    generate_world,
    lift_shares,
    needles,
    out_of_reach,
    study_world,
    world_toml,
)

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def one_line_error(result, *needles):
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, result.output
    assert lines[0].startswith("Error: "), result.output
    for n in needles:
        assert n in lines[0], result.output


def test_world_writes_the_generated_file(tmp_path):
    out = tmp_path / "w.toml"
    r = invoke(
        "world", "--seed", 7, "--niches", 4, "--family", "collab", "--inversion",
        "--mass", "3,20", "--obstacles", 2, "--out", out,
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    assert not r.stderr.strip() and f"Wrote {out}" in r.stdout and "4 niches" in r.stdout
    w = generate_world(7, niches=4, family="collab", inversion=True, mass=(3.0, 20.0), obstacles=2)
    assert out.read_text(encoding="utf-8") == world_toml(w)
    assert load_scenario(str(out)) == w.scenario
    assert [f for f in os.listdir(tmp_path)] == ["w.toml"]  # no temporary file left


def test_world_prints_the_file_without_out():
    r = invoke("world", "--seed", 3, "--niches", 2, "--effectors", "suction")
    assert r.exit_code == 0, r.output
    assert r.stdout == world_toml(generate_world(3, niches=2, effectors=("suction",)))


def test_world_min_lift_share_redraws_and_refuses_in_one_line():
    # without the reach check (no overlapping world of seed 0 passes both)
    args = ("world", "--seed", 0, "--niches", 3, "--bands", "overlapping", "--mass", "2,120")
    args += ("--min-reach", 0)
    r = invoke(*args, "--min-lift-share", 0.01)
    assert r.exit_code == 0, r.output
    kw = dict(niches=3, bands="overlapping", mass=(2.0, 120.0), min_reach=0.0)
    assert r.stdout == world_toml(generate_world(0, **kw, min_lift_share=0.01))
    assert r.stdout != world_toml(generate_world(0, **kw))
    one_line_error(invoke(*args, "--min-lift-share", 0.2), "fewer than min_lift_share 20.00%")
    one_line_error(invoke("world", "--min-lift-share", 2), "min_lift_share: must be in")


@pytest.mark.parametrize("split, index", [("train", 0), ("test", 11)])
def test_world_writes_a_study_world(tmp_path, split, index):
    out = tmp_path / "s.toml"
    r = invoke("world", "--split", split, "--index", index, "--out", out)
    assert r.exit_code == 0, r.output
    w = study_world(split, index)
    assert out.read_text(encoding="utf-8") == world_toml(w)
    assert f"study-{split}-{index:02d}" in r.stdout


def test_world_refuses_to_overwrite_without_force(tmp_path):
    out = tmp_path / "w.toml"
    out.write_text("keep me", encoding="utf-8")
    one_line_error(invoke("world", "--out", out), "exists", "--force")
    assert out.read_text(encoding="utf-8") == "keep me"
    r = invoke("world", "--seed", 5, "--out", out, "--force")
    assert r.exit_code == 0, r.output
    assert out.read_text(encoding="utf-8") == world_toml(generate_world(5))


def test_world_refuses_a_link_a_folder_and_a_missing_folder(tmp_path):
    target = tmp_path / "target.toml"
    target.write_text("target", encoding="utf-8")
    link = tmp_path / "link.toml"
    link.symlink_to(target)
    one_line_error(invoke("world", "--out", link, "--force"), "symbolic link")
    assert target.read_text(encoding="utf-8") == "target" and link.is_symlink()
    one_line_error(invoke("world", "--out", tmp_path, "--force"), "is a directory")
    one_line_error(invoke("world", "--out", tmp_path / "no" / "w.toml"), "does not exist")
    assert sorted(os.listdir(tmp_path)) == ["link.toml", "target.toml"]


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--mass", "300,400"], "lifts more than"),
        (["--mass", "3"], "--mass expects LO,HI"),
        (["--distance", "a,b"], "--distance expects LO,HI"),
        (["--mass", "nan,5"], "mass:"),
        (["--niches", "9"], "niches: must be in [1, 6]"),
        (["--niches", "2", "--family", "single"], "family 'single' has 1 niche"),
        (["--family", "many"], "--family"),
        (["--bands", "crossed"], "--bands"),
        (["--effectors", "pincher,gripper"], "unknown effector 'gripper'"),
        (["--niches", "3", "--bands", "overlapping"], "raise the mass range"),
        (["--budget", "500"], "budget: $500.00 cannot field 20 robots"),
        (["--num-robots", "2"], "num_robots: 2 robots cannot field"),
        (["--seed", "-1"], "seed"),
        (["--split", "train"], "--split and --index go together"),
        (["--index", "2"], "--split and --index go together"),
        (
            ["--split", "test", "--index", "2", "--niches", "3"],
            "--split takes no generator options",
        ),
        (["--split", "test", "--index", "15"], "index: expected an integer in [0, 14]"),
        (["--split", "validation", "--index", "1"], "--split"),
    ],
)
def test_world_bad_options_give_one_line_errors(tmp_path, args, needle):
    out = tmp_path / "w.toml"
    one_line_error(invoke("world", *args, "--out", out), needle)
    assert not out.exists()


def test_world_warns_of_each_needle_class_on_stderr_and_prints_the_world_unchanged(tmp_path):
    w = study_world("train", 14)
    shares = lift_shares(w.scenario)
    low = [i for i, s in enumerate(shares) if s < NEEDLE_SHARE]
    assert needles(w.scenario) == [(i, shares[i]) for i in low] and len(low) >= 2
    r = invoke("world", "--split", "train", "--index", 14)
    assert r.exit_code == 0, r.output
    assert r.stdout == world_toml(w)  # the TOML alone on stdout
    # the needles first, then the niches out of reach (a study world is drawn without the check)
    far = out_of_reach(w.scenario, w.niche_designs)
    lines = r.stderr.splitlines()
    assert len(lines) == len(low) + len(far) and far
    for line, (i, share) in zip(lines[len(low) :], far):
        assert line.startswith(f"Warning: niche {i + 1} ({w.niche_designs[i].label}) is out of")
        assert f"brings home {share:.0%} of its packages" in line and "--min-reach 0.5" in line
    for line, i in zip(lines, low):
        assert line.startswith(f"Warning: class {i}'s heaviest package is lifted by ")
        assert "--min-lift-share 0.01" in line
    out = tmp_path / "w.toml"
    r = invoke("world", "--split", "train", "--index", 14, "--out", out)
    assert r.exit_code == 0 and len(r.stderr.splitlines()) == len(low) + len(far)
    assert out.read_text(encoding="utf-8") == world_toml(w)
    # a world without a needle, its niches within reach: no warning
    w3 = study_world("train", 3)
    assert not needles(w3.scenario) and not out_of_reach(w3.scenario, w3.niche_designs)
    assert not invoke("world", "--split", "train", "--index", 3).stderr.strip()


def test_world_min_reach_redraws_a_world_with_a_niche_out_of_reach_and_warns_without_it():
    args = ("world", "--seed", 6, "--niches", 4)
    plain = generate_world(6, niches=4, min_reach=0.0)
    far = out_of_reach(plain.scenario, plain.niche_designs)
    assert [i for i, _ in far] == [0]  # niche 1, far from the base
    r = invoke(*args, "--min-reach", 0)
    assert r.exit_code == 0 and r.stdout == world_toml(plain)
    assert r.stdout.splitlines()[1].endswith("--min-reach 0")
    (line,) = r.stderr.splitlines()
    assert line.startswith("Warning: niche 1 (pincher, robots ") and "out of reach" in line
    # the default draws another world whose niches are all within reach, and says nothing
    r = invoke(*args)
    drawn = generate_world(6, niches=4)
    assert r.exit_code == 0 and r.stdout == world_toml(drawn) and not r.stderr.strip()
    assert drawn.scenario != plain.scenario and not out_of_reach(
        drawn.scenario, drawn.niche_designs
    )
    assert "--min-reach 0.5" in r.stdout.splitlines()[1]
    one_line_error(invoke(*args, "--min-reach", 2), "min_reach: must be in [0, 1]")
