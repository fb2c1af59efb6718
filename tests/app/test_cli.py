"""The command line: evolve, resume, inspect, scenarios, and every kind of bad input."""

import json
import re
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from swarmcode_torch.app.cli import app
from swarmcode_torch.sim.scenario import builtin_names, load_scenario

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
]


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def only_run(logdir: Path) -> Path:
    runs = list(logdir.iterdir())
    assert len(runs) == 1, runs
    return runs[0]


def assert_clean_error(result, *needles):
    assert result.exit_code != 0
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    for n in needles:
        assert n in result.output, result.output


def test_scenarios_lists_every_builtin():
    r = invoke("scenarios")
    assert r.exit_code == 0, r.output
    for name in builtin_names():
        assert name in r.output


def test_scenarios_off_a_terminal_prints_whole_descriptions(monkeypatch):
    from dataclasses import replace

    import swarmcode_torch.app.cli as cli

    r = invoke("scenarios")  # CliRunner's output is not a terminal
    for name in builtin_names():
        assert load_scenario(name).description in r.output, name
    long = "a very long description, " * 12 + "the end"
    monkeypatch.setattr(cli, "load_scenario", lambda n: replace(load_scenario(n), description=long))
    r = invoke("scenarios")
    assert r.exit_code == 0 and r.output.count(long) == len(builtin_names())


def test_device_and_objective_offer_their_choices_in_help_and_completion():
    r = runner.invoke(app, ["evolve", "--help"], env={"COLUMNS": "200"})
    assert "--objective <fitness|roi>" in r.output
    assert "--device [auto|cpu|cuda|cuda:N]" in r.output
    r = runner.invoke(app, ["sweep", "--help"], env={"COLUMNS": "200"})
    assert "--objective <fitness|roi>" in r.output and "[auto|cpu|cuda|cuda:N]" in r.output
    assert "--install-completion" in runner.invoke(app, ["--help"]).output

    def complete(words: str) -> list[str]:
        r = runner.invoke(
            app,
            [],
            prog_name="swarmcode-torch",
            env={
                "_SWARMCODE_TORCH_COMPLETE": "complete_bash",
                "COMP_WORDS": words,
                "COMP_CWORD": str(len(words.split(" ")) - 1),
            },
        )
        assert r.exit_code == 0, r.output
        return r.output.split()

    assert complete("swarmcode-torch evolve --objective ") == ["fitness", "roi"]
    assert complete("swarmcode-torch sweep --objective r") == ["roi"]
    assert complete("swarmcode-torch evolve --device ") == ["auto", "cpu", "cuda", "cuda:0"]
    assert complete("swarmcode-torch evolve --device cu") == ["cuda", "cuda:0"]
    assert_clean_error(invoke("evolve", "--objective", "profit"), "--objective", "'fitness', 'roi'")


def test_evolve_writes_a_complete_run_directory(tmp_path):
    r = invoke("evolve", *TINY, "--generations", 2, "--logdir", tmp_path, "--budget", 900)
    assert r.exit_code == 0, r.output
    run = only_run(tmp_path)
    for f in ("config.toml", "checkpoint.pt", "summary.json"):
        assert (run / f).is_file()
    assert list(run.glob("events.out.tfevents.*"))
    summary = json.loads((run / "summary.json").read_text())
    assert (summary["generation"], summary["generations"]) == (1, 2)
    from swarmcode_torch.sim.fused import available

    assert (summary["device"], summary["tick"]) == ("cpu", "fused" if available() else "eager")
    assert "done 2/2" in r.output and "generation 1 " in r.output  # plain lines off a terminal
    assert "done 1/2" in r.output  # the first generation is reported at once
    r = invoke("inspect", run)
    assert r.exit_code == 0, r.output
    assert "Robots per design" in r.output and "species" in r.output
    r = invoke("replay", run, "--out", tmp_path / "t.gif", "--ticks", 6, "--every", 3)
    assert r.exit_code == 0, r.output
    assert (tmp_path / "t.gif").is_file() and "deliveries" in r.output
    r = invoke("replay", run, "--generation", 1, "--ticks", 4, "--out", tmp_path / "g1.gif")
    assert r.exit_code == 0, r.output
    assert_clean_error(invoke("replay", run, "--generation", 99), "generation 99")


def test_set_writes_algorithm_keys_into_the_run_config(tmp_path):
    r = invoke(
        "evolve",
        *TINY,
        "--generations",
        1,
        "--logdir",
        tmp_path,
        "--set",
        "p_tag_flip=0.25",
        "--set",
        "w_tool=0.5",
        "--set",
        "quota_size_exponent=none",
        "--set",
        "dominance=false",
    )
    assert r.exit_code == 0, r.output
    run = only_run(tmp_path)
    from swarmcode_torch.app.runs import read_config

    cfg = read_config(run)
    assert (cfg.p_tag_flip, cfg.w_tool, cfg.dominance) == (0.25, 0.5, False)
    assert cfg.quota_size_exponent is None  # written "none": its default is 0.75
    assert_clean_error(invoke("evolve", "--resume", run, "--set", "delta=0.5"), "--set")
    # a retired setting is an unknown key
    assert_clean_error(
        invoke(
            "evolve",
            *TINY,
            "--generations",
            1,
            "--logdir",
            tmp_path / "b",
            "--set",
            "quota_basis=mean",
        ),
        "quota_basis",
    )


def test_preset_paper_runs_the_papers_rules_and_is_recorded(tmp_path):
    import json

    from swarmcode_torch.app.runs import read_config

    r = invoke(
        "evolve",
        *TINY,
        "--generations",
        1,
        "--logdir",
        tmp_path,
        "--preset",
        "paper",
        "--set",
        "p_tag_flip=0.25",
    )
    assert r.exit_code == 0, r.output
    run = only_run(tmp_path)
    cfg = read_config(run)
    assert (cfg.preset, cfg.partners_per_niche, cfg.partner_admission) == ("paper", "all", "open")
    assert (cfg.quota_size_exponent, cfg.p_effector, cfg.p_tag_flip) == (None, None, 0.25)
    assert json.loads((run / "summary.json").read_text())["preset"] == "paper"
    assert_clean_error(
        invoke("evolve", *TINY, "--generations", 1, "--logdir", tmp_path / "b", "--preset", "fast"),
        "unknown preset 'fast'",
        "default, paper",
    )
    assert_clean_error(invoke("evolve", "--resume", run, "--preset", "default"), "--preset")
    assert_clean_error(
        invoke("evolve", *TINY, "--logdir", tmp_path / "c", "--set", "preset=paper"),
        "use the --preset option",
    )
    r = invoke("evolve", *TINY, "--generations", 1, "--logdir", tmp_path / "d")
    assert r.exit_code == 0, r.output
    assert read_config(only_run(tmp_path / "d")).preset == "default"


def test_resume_extends_a_finished_run(tmp_path):
    assert invoke("evolve", *TINY, "--generations", 2, "--logdir", tmp_path).exit_code == 0
    run = only_run(tmp_path)
    r = invoke("evolve", "--resume", run, "--generations", 3)
    assert r.exit_code == 0, r.output
    assert "Resuming" in r.output and "done 3/3" in r.output
    d = torch.load(run / "checkpoint.pt", weights_only=True)
    assert d["generation"] == 3
    assert "generations = 3" in (run / "config.toml").read_text()


@pytest.mark.parametrize(
    "args,needles",
    [
        (["--budget", "-5"], ["--budget must be > 0"]),
        (["--population", "1"], ["--population must be >= 2"]),
        (["--generations", "0"], ["--generations must be >= 1"]),
        (["--objective", "profit"], ["--objective"]),
        (["--scenario", "nowhere"], ["unknown scenario", "four-niche", "budget"]),
        (["--scenario", "missing/file.toml"], ["not found"]),
        (["--device", "tpu"], ["--device"]),
        (["--set", "foo=1"], ["unknown key 'foo'", "p_tag_flip"]),
        (["--set", "delta=wide"], ["--set delta: expected a value of type float"]),
        (["--set", "delta"], ["KEY=VALUE"]),
        (["--set", "seed=4"], ["use the --seed option"]),
        (["--set", "p_tag_flip=1.5"], ["p_tag_flip must be <= 1"]),
        (["--set", "delta=nan"], ["delta must be a finite number"]),
    ],
)
def test_bad_options_give_one_line_errors(tmp_path, args, needles):
    r = invoke("evolve", "--logdir", tmp_path, *args)
    assert_clean_error(r, *needles)
    assert not tmp_path.exists() or not any(tmp_path.iterdir())  # no run directory left behind


@pytest.mark.skipif(torch.cuda.is_available(), reason="CUDA is present here")
def test_cuda_without_cuda_is_a_clear_error(tmp_path):
    assert_clean_error(invoke("evolve", "--device", "cuda", "--logdir", tmp_path), "no CUDA")


def test_malformed_scenario_file_names_the_field(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(
        'name = "x"\narena = 20.0\nbase_radius = 1.0\nnum_robots = "many"\n'
        'episode_ticks = 10\n[[packages]]\nkind = "individual"\neffector = "pincher"\n'
        "count = 1\ndistance = [2.0, 4.0]\nmass = [1.0, 2.0]\n"
    )
    assert_clean_error(
        invoke("evolve", "--scenario", bad, "--logdir", tmp_path / "runs"), "num_robots"
    )
    bad.write_text("this is = not [toml")
    assert_clean_error(
        invoke("evolve", "--scenario", bad, "--logdir", tmp_path / "runs"), "not valid TOML"
    )


def test_corrupt_and_incompatible_checkpoints(tmp_path):
    assert invoke("evolve", *TINY, "--generations", 1, "--logdir", tmp_path).exit_code == 0
    run = only_run(tmp_path)
    good = (run / "checkpoint.pt").read_bytes()
    (run / "checkpoint.pt").write_bytes(b"\x00garbage" * 10)
    assert_clean_error(invoke("evolve", "--resume", run, "--generations", 2), "corrupt")
    (run / "checkpoint.pt").write_bytes(good)
    cfg = (run / "config.toml").read_text()
    (run / "config.toml").write_text(cfg.replace("population = 6", "population = 8"))
    assert_clean_error(invoke("evolve", "--resume", run, "--generations", 2), "does not match")
    (run / "config.toml").write_text("population = [")
    assert_clean_error(invoke("evolve", "--resume", run), "malformed config")
    assert_clean_error(invoke("evolve", "--resume", tmp_path / "nope"), "not a run directory")
    assert_clean_error(invoke("evolve", "--resume", run, "--population", 9), "--resume")


def test_inspect_of_a_non_run_is_an_error(tmp_path):
    assert_clean_error(invoke("inspect", tmp_path), "summary.json")
    assert_clean_error(invoke("inspect", tmp_path / "absent"), "not a directory")


def test_sweep_writes_table_iii_and_resumes(tmp_path):
    out = tmp_path / "sweep"
    args = [
        "sweep",
        "--budgets",
        "1500,3000",
        "--seeds",
        "0",
        "--scenario",
        "one-niche",
        "--generations",
        1,
        "--population",
        6,
        "--swarm-size",
        4,
        "--trials",
        1,
        "--ticks",
        10,
        "--out",
        out,
    ]
    r = invoke(*args)
    assert r.exit_code == 0, r.output
    table = (out / "table.md").read_text().splitlines()
    assert table[0].startswith("| Budget | Best fitness | Team cost")
    assert [line.split("|")[1].strip() for line in table[2:4]] == ["1500", "3000"]
    assert (out / "table.csv").read_text().count("\n") == 3 and (out / "budget.png").is_file()
    r = invoke(*args)
    assert r.exit_code == 0 and r.output.count("already done") == 2
    # inspect on the sweep directory: its table, where it is, and its runs
    r = invoke("inspect", out)
    assert r.exit_code == 0, r.output
    lines = r.output.splitlines()
    assert lines[: len(table)] == table
    assert f"Table: {out / 'table.md'}, {out / 'table.csv'}" in lines
    assert "  budget-1500_seed-0: 1/1 generations" in lines
    assert "  budget-3000_seed-0: 1/1 generations" in lines
    assert f"Inspect a run: swarmcode-torch inspect {out / 'budget-1500_seed-0'}" in lines
    (out / "table.md").unlink()  # a sweep that has not finished
    r = invoke("inspect", out)
    assert r.exit_code == 0 and "without a table yet" in r.output, r.output
    assert "  budget-3000_seed-0: 1/1 generations" in r.output.splitlines()
    assert_clean_error(invoke("sweep", "--budgets", "10,abc"), "--budgets")
    assert_clean_error(invoke("sweep", "--budgets", "-1", "--out", tmp_path / "x"), "--budget")


def test_sweep_logdir_holds_a_new_sweep_directory_as_evolves_holds_runs(tmp_path):
    logdir = tmp_path / "runs"
    args = [
        "sweep",
        "--budgets",
        "1500",
        "--scenario",
        "one-niche",
        "--generations",
        1,
        "--population",
        6,
        "--swarm-size",
        4,
        "--trials",
        1,
        "--ticks",
        8,
    ]
    r = invoke(*args, "--logdir", logdir)
    assert r.exit_code == 0, r.output
    sweep = only_run(logdir)
    assert sweep.name.startswith("sweep-") and (sweep / "table.md").is_file()
    assert (sweep / "budget-1500_seed-0" / "summary.json").is_file()
    assert f"Sweep directory: {sweep} (resume with --out {sweep})" in " ".join(r.output.split())
    r = invoke(*args, "--out", sweep)  # resumed by its own directory
    assert r.exit_code == 0 and "already done" in r.output, r.output
    assert_clean_error(
        invoke(*args, "--logdir", logdir, "--out", sweep), "--logdir and --out cannot both be given"
    )
    (tmp_path / "file").write_text("")
    assert_clean_error(invoke(*args, "--logdir", tmp_path / "file"), "is not a directory")
    r = runner.invoke(app, ["sweep", "--help"], env={"COLUMNS": "200"})
    assert "--logdir" in r.output and "sweep-<time>" in r.output


def test_sweep_set_applies_to_every_run_and_refuses_clearly(tmp_path):
    out = tmp_path / "sweep"
    r = invoke(
        "sweep",
        "--budgets",
        "1500",
        "--scenario",
        "one-niche",
        "--generations",
        1,
        "--population",
        6,
        "--swarm-size",
        4,
        "--trials",
        1,
        "--ticks",
        10,
        "--out",
        out,
        "--set",
        "p_tag_flip=0.5",
        "--set",
        "min_share=0",
    )
    assert r.exit_code == 0, r.output
    from swarmcode_torch.app.runs import read_config

    cfg = read_config(out / "budget-1500_seed-0")
    assert (cfg.p_tag_flip, cfg.min_share) == (0.5, 0.0)
    assert_clean_error(
        invoke("sweep", "--set", "seed=3", "--out", tmp_path / "a"), "use the --seeds option"
    )
    if not torch.cuda.is_available():
        bad = tmp_path / "b"
        assert_clean_error(
            invoke(
                "sweep",
                "--budgets",
                "1500",
                "--device",
                "cpu",
                "--set",
                "cuda_graphs=true",
                "--out",
                bad,
            ),
            "cuda_graphs",
        )
        assert not any(bad.iterdir())  # no run directory left behind


def _entry_point_command() -> list[str]:
    """The `swarmcode-torch` script as pyproject.toml declares it, run by this interpreter (the
    installed script may belong to another checkout)."""
    import sys

    import tomllib

    spec = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())
    module, func = spec["project"]["scripts"]["swarmcode-torch"].split(":")
    return [
        sys.executable,
        "-c",
        f"import sys; sys.argv[0] = 'swarmcode-torch'; from {module} import {func}; {func}()",
    ]


@pytest.mark.parametrize("entry", ["script", "module"])
def test_no_arguments_print_the_top_level_help_as_click_does(entry):
    # with no command: the help --help prints, on stderr, exit 2 (click's no-args convention)
    import subprocess
    import sys

    cmd = _entry_point_command() if entry == "script" else [sys.executable, "-m", "swarmcode_torch"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    helped = subprocess.run([*cmd, "--help"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and helped.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr and r.stdout == ""
    assert r.stderr.strip() == helped.stdout.strip()
    for command in ("evolve", "sweep", "inspect", "replay", "dynamics", "scenarios"):
        assert f"  {command} " in r.stderr


def test_no_arguments_print_the_help_through_the_runner():
    r = runner.invoke(app, [])
    assert r.exit_code == 2
    assert "Usage:" in r.stderr and "Commands:" in r.stderr and "evolve" in r.stderr


def test_evolve_help_shows_the_defaults_of_scenario_and_generations():
    from swarmcode_torch.coevo.config import SwarmCoDeConfig

    default = SwarmCoDeConfig()
    r = runner.invoke(app, ["evolve", "--help"])
    assert r.exit_code == 0
    text = " ".join(r.output.split())  # help wrapped over lines, joined
    helps = dict(re.findall(r"(--[a-z-]+) <\w+> (.*?)(?= --[a-z])", text))
    assert f"[default: {default.scenario}]" in helps["--scenario"], helps["--scenario"]
    assert f"[default: {default.generations};" in helps["--generations"], helps["--generations"]
