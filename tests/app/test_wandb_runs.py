"""What W&B gets besides the scalars (`wandb_runs`): the run's checkpoint and replays as an
artifact at its end, and a sweep's runs grouped and tagged. Offline (WANDB_MODE=offline), read
back from the records wandb wrote; a failing artifact upload with a recorder in place of wandb."""

import base64
import hashlib
import types

import pytest
from test_wandb import RUN, _records, offline  # noqa: F401 - offline is a fixture
from typer.testing import CliRunner

import swarmcode_torch as sc
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.report_wandb import _wandb_run_id

SWEEP = [
    "sweep",
    *[a for a in RUN[1:] if a not in ("--render-every", "2", "--budget", "700", "--seed", "4")],
    "--budgets",
    "300,600",
    "--seeds",
    "5",
    "--wandb",
    "--wandb-project",
    "sweep-test",
]


def _wandb_records(run_dir):
    """{W&B offline run directory name: its records}, in the order they were made."""
    return [
        _records(next(d.glob("run-*.wandb")))
        for d in sorted((run_dir / "wandb").glob("offline-run-*"))
    ]


def _artifact(records):
    (art,) = [x.artifact for x in records if x.WhichOneof("record_type") == "artifact"]
    return art


def _md5(path) -> str:
    return base64.b64encode(hashlib.md5(path.read_bytes()).digest()).decode()


@pytest.mark.subprocess
def test_sweep_runs_are_grouped_tagged_and_their_files_logged(tmp_path, offline):  # noqa: F811
    out = tmp_path / "my-sweep"
    r = CliRunner().invoke(app, [*SWEEP, "--generations", "2", "--out", str(out)])
    assert r.exit_code == 0, r.output
    for budget in (300, 600):
        run_dir = out / f"budget-{budget}_seed-5"
        (records,) = _wandb_records(run_dir)
        (run,) = [x.run for x in records if x.WhichOneof("record_type") == "run"]
        assert run.project == "sweep-test" and run.run_group == "my-sweep"
        assert list(run.tags) == ["sweep", f"budget-{budget}", "seed-5"]
        assert run.run_id == _wandb_run_id(run_dir) and run.display_name == run_dir.name
        art = _artifact(records)
        assert art.type == "swarmcode-run" and art.name == f"run-{run_dir.name}"
        # the checkpoint as the run left it; no replays were made
        (entry,) = art.manifest.contents
        assert entry.path == "checkpoint.pt" and entry.digest == _md5(run_dir / "checkpoint.pt")
    # replays made since (by `replay`) go with the checkpoint when the run goes on
    run_dir = out / "budget-300_seed-5"
    (run_dir / "team.gif").write_bytes(b"GIF89a replay")
    (run_dir / "team.html").write_text("<html>replay</html>")
    r = CliRunner().invoke(app, [*SWEEP, "--generations", "3", "--out", str(out)])
    assert r.exit_code == 0, r.output
    first, resumed = _wandb_records(run_dir)
    (run,) = [x.run for x in resumed if x.WhichOneof("record_type") == "run"]
    assert run.run_id == _wandb_run_id(run_dir) and run.run_group == "my-sweep"
    entries = {e.path: e.digest for e in _artifact(resumed).manifest.contents}
    assert sorted(entries) == ["checkpoint.pt", "team.gif", "team.html"]
    for name, digest in entries.items():
        assert digest == _md5(run_dir / name), name


def test_bad_wandb_project_of_a_sweep_is_one_line_before_anything_is_made(tmp_path, offline):  # noqa: F811
    out = tmp_path / "s"
    r = CliRunner().invoke(app, [*SWEEP[:-1], "a/b", "--out", str(out)])
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert r.exit_code == 2 and len(lines) == 1 and "wandb project" in lines[0], r.output
    assert not out.exists()


class _Recorder:
    """A stand-in for the wandb module: records init keywords, logs, artifacts and finishes."""

    def __init__(self, fail_artifact: bool):
        self.inits, self.logged, self.artifacts, self.finished = [], [], [], 0
        self.fail_artifact = fail_artifact
        rec = self

        class Run:
            def log(self, row, step=None):
                rec.logged.append((step, sorted(row)))

            def log_artifact(self, art):
                if rec.fail_artifact:
                    raise RuntimeError("upload refused")
                rec.artifacts.append(art)

            def finish(self):
                rec.finished += 1

        class Artifact:
            def __init__(self, name, type, description=""):
                self.name, self.type, self.files = name, type, {}

            def add_file(self, path, name):
                self.files[name] = open(path, "rb").read()

        self.module = types.SimpleNamespace(
            init=lambda **kw: (self.inits.append(kw), Run())[1],
            Artifact=Artifact,
            Histogram=lambda values: ("histogram", len(values)),
            Image=lambda image, caption="": ("image", caption),
        )


@pytest.mark.parametrize("fail_artifact", [False, True])
def test_the_artifact_is_the_final_checkpoint_and_a_failure_one_warning(
    tmp_path, monkeypatch, fail_artifact
):
    rec = _Recorder(fail_artifact)
    monkeypatch.setitem(__import__("sys").modules, "wandb", rec.module)
    kw = dict(
        scenario="one-niche",
        population=4,
        swarm_size=3,
        trials=1,
        ticks=6,
        generations=2,
        device="cpu",
        compile=False,
        logdir=tmp_path / "runs",
        render_every=0,
        wandb="p",
        progress=False,
    )
    if fail_artifact:
        with pytest.warns(RuntimeWarning, match="logging stopped .*upload refused"):
            result = sc.evolve(**kw)
        assert rec.artifacts == []
    else:
        result = sc.evolve(**kw)
        (art,) = rec.artifacts
        assert art.files == {"checkpoint.pt": (result.run_dir / "checkpoint.pt").read_bytes()}
    assert rec.finished == 1 and [s for s, _ in rec.logged] == [0, 1]
    assert "group" not in rec.inits[0]  # a run outside a sweep has none
