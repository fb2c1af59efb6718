"""Every option of evolve and sweep is declared once (`run_options.RUN_OPTIONS`): the command
line, the API's keywords, the --set refusals, the bound checks and a run's config.toml follow
the declaration; a bad value in a --config file names the file and its key."""

import inspect
import re
import sys

import pytest
import typer
from typer.testing import CliRunner

import swarmcode_torch as sc
from swarmcode_torch.app import api, evolve_start, options, run_options
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.optspec import (
    UNSET,
    Intervals,
    Opt,
    Values,
    api_signature,
    api_values,
    for_command,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

runner = CliRunner()
TINY = ["--scenario", "one-niche", "--population", "6", "--swarm-size", "4", "--trials", "1"]
TINY += ["--ticks", "15", "--seed", "3", "--device", "cpu", "--no-compile", "--render-every", "0"]


def invoke(*args, target=app):
    return runner.invoke(target, [str(a) for a in args], env={"COLUMNS": "200"})


def assert_clean_error(result, *needles):
    assert result.exit_code != 0, result.output
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    for n in needles:
        assert n in result.output, result.output


def click_params(name: str) -> dict:
    """The click parameters of a command of the app, by Python name."""
    command = typer.main.get_command(app).commands[name]
    return {p.name: p for p in command.params}


@pytest.mark.parametrize("command", ["evolve", "sweep"])
def test_the_commands_take_exactly_the_declared_options(command):
    declared = for_command(run_options.RUN_OPTIONS, command)
    params = click_params(command)
    assert list(params) == [o.name for o in declared]
    for o in declared:
        p = params[o.name]
        assert p.help == o.help, o.name
        assert o.spelling in p.opts, (o.name, p.opts)
        default = o.default.value if hasattr(o.default, "value") else o.default
        assert p.default == default, o.name
    help_text = " ".join(invoke(command, "--help").output.split())
    for o in declared:
        assert o.spelling in help_text and " ".join(o.help.split()) in help_text, o.name


def test_sweep_shares_the_declarations_of_evolve():
    evolve = {o.name: o for o in run_options.EVOLVE_OPTIONS}
    sweep = {o.name: o for o in run_options.SWEEP_OPTIONS}
    shared = set(evolve) & set(sweep)
    assert {"scenario", "generations", "checkpoint_every", "log_every", "settings"} <= shared
    for name in shared:
        e, s = evolve[name], sweep[name]
        assert (e.type, e.setting, e.interval, e.low, e.flags) == (
            s.type,
            s.setting,
            s.interval,
            s.low,
            s.flags,
        ), name
    assert sweep["log_every"].default == 50 and evolve["log_every"].default == 10


def test_the_api_signature_is_the_declared_keywords_and_its_own():
    sig = inspect.signature(sc.evolve)
    params = sig.parameters
    declared = [o for o in run_options.EVOLVE_OPTIONS if o.api]
    for o in declared:
        p = params[o.name]
        assert p.kind is inspect.Parameter.KEYWORD_ONLY, o.name
        assert p.default == o.keyword().default, o.name
        assert p.default is (UNSET if o.setting and o.name != "scenario" else p.default), o.name
    assert params["logdir"].default == "runs" and params["checkpoint_every"].default == 10
    assert params["render_every"].default == 50 and params["snapshot_every"].default == 0
    own = ["reporters", "callback", "fitness", "wandb", "progress"]
    assert [n for n in params if n in own] == own
    assert list(params)[0] == "config" and list(params)[-1] == "settings"
    # the declared keywords bind as written: a call the signature refuses is refused
    sig.bind(None, generations=2, delta=0.5, checkpoint_every=3)
    with pytest.raises(TypeError):
        sig.bind(None, 2)


def test_the_api_keeps_unset_and_none_apart():
    evolve = run_options.EVOLVE_OPTIONS
    own, settings = api_values(evolve, {"budget": None, "generations": 4, "delta": 0.5})
    assert settings == {"budget": None, "generations": 4, "delta": 0.5}  # None unsets a budget
    own, settings = api_values(evolve, {})
    assert settings == {} and own.logdir == "runs" and own.checkpoint_every == 10
    assert own.intervals(evolve) == Intervals(
        checkpoint=10, log=10, render=50, figure=50, snapshot=0
    )


DUMMY = Opt(
    "delta",
    float | None,
    help="Dummy: the species distance threshold, as an option.",
    setting="delta",
    commands=("evolve", "sweep"),
    api=True,
)


def test_a_dummy_option_declared_in_one_place_reaches_help_api_and_config(monkeypatch, tmp_path):
    table = (*run_options.RUN_OPTIONS, DUMMY)
    monkeypatch.setattr(run_options, "RUN_OPTIONS", table)  # --set delta now names --delta
    evolve = for_command(table, "evolve")
    cmd = typer.Typer()
    cmd.command("evolve")(options.command(evolve, evolve_start.evolve_command, "evolve", "doc"))

    assert "Dummy: the species distance threshold" in invoke("--help", target=cmd).output
    shown = invoke(*TINY, "--delta", "0.7", "--print-config", target=cmd)
    assert shown.exit_code == 0, shown.output
    assert tomllib.loads(shown.output)["delta"] == 0.7
    r = invoke(*TINY, "--delta", "0.7", "--generations", "1", "--logdir", tmp_path, target=cmd)
    assert r.exit_code == 0, r.output
    (run,) = tmp_path.iterdir()
    assert tomllib.loads((run / "config.toml").read_text())["delta"] == 0.7
    assert_clean_error(invoke(*TINY, "--delta", "-1", target=cmd), "--delta must be")
    assert_clean_error(invoke(*TINY, "--set", "delta=0.5", target=cmd), "use the --delta option")

    sig = api_signature(api.evolve, evolve)
    assert sig.parameters["delta"].default is UNSET
    assert sig.parameters["delta"].kind is inspect.Parameter.KEYWORD_ONLY
    monkeypatch.setattr(api, "EVOLVE_OPTIONS", evolve)
    result = sc.evolve(
        logdir=tmp_path / "api", delta=0.6, progress=False, **_api_tiny(generations=1)
    )
    assert tomllib.loads((result.run_dir / "config.toml").read_text())["delta"] == 0.6
    sweep = for_command(table, "sweep")
    assert [o.name for o in sweep][-1] == "delta"


def _api_tiny(**kw):
    return dict(
        scenario="one-niche",
        population=6,
        swarm_size=4,
        trials=1,
        ticks=15,
        seed=3,
        device="cpu",
        compile=False,
        render_every=0,
        **kw,
    )


@pytest.mark.parametrize(
    "opt", [o for o in run_options.EVOLVE_OPTIONS if o.low is not None], ids=lambda o: o.name
)
def test_every_declared_bound_is_checked_with_the_options_name(opt, tmp_path):
    below = opt.low - 1
    r = invoke("evolve", *TINY, opt.spelling, below, "--logdir", tmp_path)
    assert_clean_error(r, f"{opt.spelling} must be >= {opt.low:g}")
    assert not any(tmp_path.iterdir())
    if opt.api:
        with pytest.raises(ValueError, match=f"{opt.name} must be >= {opt.low:g}"):
            sc.evolve(logdir=tmp_path, **{**_api_tiny(), opt.name: below})
        with pytest.raises(TypeError, match=f"{opt.name} must be an integer"):
            sc.evolve(logdir=tmp_path, **{**_api_tiny(), opt.name: 2.5})


@pytest.mark.parametrize("opt", [o for o in run_options.RUN_OPTIONS if o.setting])
def test_set_refuses_every_key_that_has_an_option(opt):
    r = invoke("evolve", "--set", f"{opt.setting}=1")
    assert_clean_error(r, f"--set {opt.setting}: use the {opt.spelling} option")


def test_resume_names_every_option_that_would_change_the_config(tmp_path):
    r = invoke("evolve", "--resume", tmp_path, "--seed", 4, "--set", "delta=1", "--preset", "paper")
    assert_clean_error(
        r, "only --generations and --device may change (got --seed, --preset, --set)"
    )


def test_a_bad_value_in_a_config_file_names_the_file_and_the_key(tmp_path):
    path = tmp_path / "settings.toml"
    path.write_text("delta = -1.0\npopulation = 8\n")
    r = invoke("evolve", "--config", path, "--print-config")
    assert_clean_error(r, f"{path}: delta must be")
    assert "--set delta" not in r.output
    # the value --set or an option gives is theirs to answer for, the file's others the file's
    assert_clean_error(
        invoke("evolve", "--config", path, "--set", "delta=-2", "--print-config"), "--set delta"
    )
    assert_clean_error(
        invoke("evolve", "--config", path, "--set", "delta=0.5", "--population", 1),
        "--population must be >= 2",
    )
    path.write_text("delta = 0.5\npopulation = 1\n")
    assert_clean_error(invoke("evolve", "--config", path), f"{path}: population must be >= 2")
    ok = invoke("evolve", "--config", path, "--population", 8, "--print-config")
    assert ok.exit_code == 0, ok.output
    assert re.search(r"^population = 8$", ok.output, re.M)


def test_values_refuse_unknown_and_clashing_names():
    with pytest.raises(TypeError, match="unknown option"):
        Values(run_options.EVOLVE_OPTIONS, {"populaton": 3})
    with pytest.raises(TypeError, match="taken by Values"):
        Values([Opt("intervals", int, 1)], {})
    v = Values(run_options.EVOLVE_OPTIONS, {"population": 3, "checkpoint_every": 4})
    assert v.population == 3 and v["seed"] is None and v.replace(seed=2).seed == 2
    assert v.intervals().checkpoint == 4 and v.config_keys() == {"population": 3}


def test_the_api_names_a_bad_value_of_a_settings_file_by_the_file_and_the_key(tmp_path):
    path = tmp_path / "settings.toml"
    path.write_text("delta = -1.0\n")
    with pytest.raises(ValueError, match=re.escape(f"{path}: delta must be")):
        sc.evolve(path, logdir=tmp_path / "runs", progress=False, **_api_tiny(generations=1))
    with pytest.raises(ValueError, match=r"^delta must be"):  # given here: named as given
        sc.evolve(path, logdir=tmp_path / "runs", delta=-2.0, **_api_tiny(generations=1))
    assert not (tmp_path / "runs").exists()


#: The options evolve and sweep gained after the declarations were written, each declared in
#: `run_options.RUN_OPTIONS` too: none is declared by hand anywhere else.
ADDED = {
    "evolve": {"stop_metric", "stop_min_delta", "stop_warmup", "stop_mode", "keep_checkpoints"},
    "sweep": {"grid", "config", "wandb", "wandb_project", "budgets"},
}


def test_the_options_added_since_are_declared_once():
    for command, names in ADDED.items():
        declared = {o.name: o for o in for_command(run_options.RUN_OPTIONS, command)}
        assert names <= set(declared), command
        help_text = " ".join(invoke(command, "--help").output.split())
        for n in names:
            assert declared[n].spelling in help_text, n
    params = inspect.signature(sc.evolve).parameters
    for n in ADDED["evolve"]:
        assert params[n].kind is inspect.Parameter.KEYWORD_ONLY, n
    # the command line's hand-written option types of evolve and sweep are gone
    assert not hasattr(options, "Evolve") and not hasattr(options, "Sweep")
    # replay's --seeds is replay's own: only evolve's and sweep's options are in the table
    assert all(set(o.commands) <= {"evolve", "sweep"} for o in run_options.RUN_OPTIONS)


def test_the_stop_and_keep_bounds_come_from_the_declarations(tmp_path):
    assert_clean_error(
        invoke("evolve", *TINY, "--keep-checkpoints", -1, "--logdir", tmp_path),
        "--keep-checkpoints must be >= 0 (0: none kept), got -1",
    )
    assert_clean_error(
        invoke("evolve", *TINY, "--patience", 2, "--stop-warmup", -3, "--logdir", tmp_path),
        "--stop-warmup must be >= 0, got -3",
    )
    assert not any(tmp_path.iterdir())
    with pytest.raises(ValueError, match=r"keep_checkpoints must be >= 0 \(0: none kept\)"):
        sc.resume(tmp_path, keep_checkpoints=-1)
    with pytest.raises(TypeError, match="stop_warmup must be an integer"):
        sc.resume(tmp_path, patience=2, stop_warmup=1.5)


def test_sweep_config_names_a_bad_value_by_the_file_and_the_key(tmp_path):
    path = tmp_path / "settings.toml"
    path.write_text("delta = -1.0\n")
    out = tmp_path / "sweep"
    sweep = ["--scenario", "one-niche", "--population", 6, "--swarm-size", 4, "--trials", 1]
    sweep += ["--ticks", 15, "--device", "cpu", "--no-compile", "--generations", 1]
    r = invoke("sweep", *sweep, "--config", path, "--out", out)
    assert_clean_error(r, f"{path}: delta must be")
    assert not out.exists()
