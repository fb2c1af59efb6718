"""Retired settings: a run directory that records one at a value this version runs alike
resumes; one at another value is read, but a resume refuses it with a one-line error."""

import pytest
import tomli_w
import torch

import swarmcode_torch as sc
from swarmcode_torch.app import runs
from swarmcode_torch.app.runs import RunError, read_config


def _run(tmp_path):
    r = sc.evolve(
        scenario="one-niche",
        population=4,
        swarm_size=3,
        trials=1,
        ticks=6,
        generations=1,
        device="cpu",
        compile=False,
        logdir=tmp_path,
    )
    return r.run_dir


def _record(run_dir, **settings):
    """The run as a version that had `settings` would have written it: in config.toml and in
    the checkpoint's config."""
    path = run_dir / runs.CONFIG_FILE
    lines = [ln for ln in path.read_text().splitlines() if ln.split(" = ")[0] not in settings]
    path.write_text("\n".join(lines) + "\n" + tomli_w.dumps(settings))
    ck = run_dir / runs.CHECKPOINT_FILE
    d = torch.load(ck, weights_only=True)
    d["config"].update(settings)
    torch.save(d, ck)


@pytest.mark.parametrize(
    "settings",
    [
        {
            "gate_margin": 0.0,
            "merge_species": False,
            "d_hw_tiers": False,
            "effector_flip": "gene",
            "bt_point_on_nodes": True,
            "baseline_refill": "any",
            "quota_inertia": 0.0,
            "evaluated_partners": False,
        },
        {"quota_basis": "mean"},  # with quota_size_exponent set it changed nothing
    ],
)
def test_a_retired_setting_at_a_value_run_alike_resumes(tmp_path, settings):
    run_dir = _run(tmp_path)
    _record(run_dir, **settings)
    assert read_config(run_dir).generations == 1
    ev = runs.resume(run_dir, generations=2)
    assert ev.state.generation == 1 and not ev.done


@pytest.mark.parametrize(
    "key,value",
    [
        ("gate_margin", 0.1),
        ("merge_species", True),
        ("effector_flip", "prototype"),
        ("d_hw_tiers", True),
        ("baseline_refill", "senior"),
        ("partner_admission", "gate"),
    ],
)
def test_a_retired_setting_at_another_value_is_read_but_not_resumed(tmp_path, key, value):
    run_dir = _run(tmp_path)
    _record(run_dir, **{key: value})
    if key != "partner_admission":  # a retired key is read, not run
        assert read_config(run_dir).population == 4
    else:  # a retired value of a kept key cannot even be read
        with pytest.raises(RunError, match="partner_admission = 'gate' is retired.*0.6.0"):
            read_config(run_dir)
    with pytest.raises(RunError) as e:
        runs.resume(run_dir, generations=2)
    msg = str(e.value)
    assert "\n" not in msg and key in msg and "0.6.0" in msg


def test_resume_of_a_retired_setting_from_the_command_line_is_one_line(tmp_path):
    from typer.testing import CliRunner

    from swarmcode_torch.app.cli import app

    run_dir = _run(tmp_path)
    _record(run_dir, merge_species=True)
    r = CliRunner().invoke(app, ["evolve", "--resume", str(run_dir), "--generations", "2"])
    assert r.exit_code != 0 and "merge_species" in r.output and "Traceback" not in r.output
