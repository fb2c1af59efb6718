"""The Weights & Biases reporter (`evolve --wandb`, `sc.evolve(wandb=...)`), run offline
(WANDB_MODE=offline: nothing goes over the network) and read back from the records the offline
run wrote: the config, a history row per generation with the scalars of metrics.csv, the
replays. Without wandb, a one-line error that names the extra."""

import json
import struct
import sys

import pytest
from typer.testing import CliRunner

import swarmcode_torch as sc
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.reporting import HPARAM_METRICS, SCALAR_TAGS, read_metrics_csv
from swarmcode_torch.app.runs import METRICS_FILE

GENERATIONS = 3
RUN = [
    "evolve",
    "--scenario",
    "one-niche",
    "--population",
    "6",
    "--swarm-size",
    "3",
    "--trials",
    "1",
    "--ticks",
    "6",
    "--seed",
    "4",
    "--device",
    "cpu",
    "--no-compile",
    "--budget",
    "700",
    "--generations",
    str(GENERATIONS),
    "--render-every",
    "2",
]


def _records(path):
    """The protobuf records of a run's .wandb file (wandb's log format: a 7-byte header, then
    32 KiB blocks of records, each with a 7-byte header: crc, length, kind (full, first,
    middle, last))."""
    from wandb.proto import wandb_internal_pb2 as pb

    data = path.read_bytes()
    assert data[:4] == b":W&B"
    pos, chunks, part = 7, [], b""
    while pos + 7 <= len(data):
        left = 32768 - pos % 32768
        if left < 7:
            pos += left
            continue
        _, length, kind = struct.unpack("<IHB", data[pos : pos + 7])
        if length == 0 and kind == 0:  # padding to the end of the block
            pos += left
            continue
        chunk, pos = data[pos + 7 : pos + 7 + length], pos + 7 + length
        if kind == 1:
            chunks.append(chunk)
        elif kind == 2:
            part = chunk
        elif kind == 3:
            part += chunk
        elif kind == 4:
            chunks.append(part + chunk)
    records = []
    for raw in chunks:
        r = pb.Record()
        r.ParseFromString(raw)
        records.append(r)
    return records


def _history(records) -> dict[int, dict]:
    """step -> the values logged at it (a nested key as 'a/b')."""
    rows: dict[int, dict] = {}
    for x in records:
        if x.WhichOneof("record_type") == "history":
            row = {
                i.key or "/".join(i.nested_key): json.loads(i.value_json) for i in x.history.item
            }
            rows.setdefault(row["_step"], {}).update(row)
    return rows


@pytest.fixture
def offline(tmp_path, monkeypatch):
    wandb = pytest.importorskip("wandb")
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_DIR", str(tmp_path / "wb"))
    monkeypatch.setenv("WANDB_SILENT", "true")
    monkeypatch.setenv("WANDB_CONSOLE", "off")
    (tmp_path / "wb").mkdir()
    yield tmp_path / "wb"
    wandb.teardown()  # the next run reads the environment again (its WANDB_DIR)


@pytest.mark.subprocess
def test_evolve_wandb_logs_the_config_scalars_and_replays_offline(tmp_path, offline):
    r = CliRunner().invoke(
        app, [*RUN, "--logdir", str(tmp_path / "runs"), "--wandb", "--wandb-project", "swarm-test"]
    )
    assert r.exit_code == 0, r.output
    (run_dir,) = (tmp_path / "runs").iterdir()
    # W&B's files are inside the run directory, not in WANDB_DIR or the working directory
    assert not (offline / "wandb").exists()
    (wb_run,) = (run_dir / "wandb").glob("offline-run-*")
    (log,) = wb_run.glob("run-*.wandb")
    records = _records(log)
    (run,) = [x.run for x in records if x.WhichOneof("record_type") == "run"]
    assert run.project == "swarm-test" and run.display_name == run_dir.name
    config = {i.key: json.loads(i.value_json) for i in run.config.update}
    assert config["population"] == 6 and config["budget"] == 700 and config["seed"] == 4
    assert config["scenario"] == "one-niche" and config["generations"] == GENERATIONS

    rows = _history(records)
    assert sorted(rows) == list(range(GENERATIONS))
    csv_rows, _ = read_metrics_csv(run_dir / METRICS_FILE)
    for g, csv_row in enumerate(csv_rows):
        for tag in SCALAR_TAGS:
            if tag.startswith("perf/"):
                continue  # timings: measured, not recorded twice the same
            assert rows[g][tag] == pytest.approx(csv_row[tag], nan_ok=True), (g, tag)
        assert set(HPARAM_METRICS) <= set(rows[g])
        assert rows[g]["traits/radius/_type"] == "histogram"
    summary = json.loads((run_dir / "summary.json").read_text())
    assert rows[GENERATIONS - 1]["best/fitness"] == pytest.approx(summary["best_fitness"])
    assert rows[GENERATIONS - 1]["best/cost"] == pytest.approx(summary["team_cost"])
    # replays: the generation's best team every 2 generations, the run's best at its end
    assert [g for g in rows if "team/replay/path" in rows[g]] == [0, 2]
    assert [g for g in rows if "best/replay/path" in rows[g]] == [GENERATIONS - 1]
    image = wb_run / "files" / rows[GENERATIONS - 1]["best/replay/path"]
    assert image.is_file() and image.read_bytes()[:4] == b"\x89PNG"


@pytest.mark.subprocess
def test_the_api_logs_to_wandb_offline(tmp_path, offline):
    result = sc.evolve(
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
        wandb="api-test",
    )
    (wb_run,) = (result.run_dir / "wandb").glob("offline-run-*")
    records = _records(next(wb_run.glob("run-*.wandb")))
    (run,) = [x.run for x in records if x.WhichOneof("record_type") == "run"]
    assert run.project == "api-test" and run.display_name == result.run_dir.name
    rows = _history(records)
    assert sorted(rows) == [0, 1] and "team/replay/path" not in rows[1]  # render_every=0
    assert rows[1]["best/fitness"] == pytest.approx(result.best_team["fitness"])


def test_without_wandb_a_one_line_error_names_the_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "wandb", None)  # `import wandb` raises ImportError
    r = CliRunner().invoke(app, [*RUN, "--logdir", str(tmp_path / "runs"), "--wandb"])
    assert r.exit_code != 0
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and "[wandb]" in lines[0], r.output
    assert "Traceback" not in r.output and not (tmp_path / "runs").exists()
    with pytest.raises(ImportError, match=r"\[wandb\]"):
        sc.evolve(
            scenario="one-niche", population=4, generations=1, logdir=tmp_path / "api", wandb="p"
        )
    assert not (tmp_path / "api").exists()


@pytest.mark.parametrize("project", ["", 123, "a/b", "x" * 200])
def test_a_bad_project_is_one_line_before_anything_is_made(tmp_path, offline, project):
    with pytest.raises(ValueError, match="wandb project"):
        sc.evolve(
            scenario="one-niche",
            population=4,
            generations=1,
            logdir=tmp_path / "api",
            wandb=project,
        )
    assert not (tmp_path / "api").exists()
    if isinstance(project, str) and project:
        r = CliRunner().invoke(
            app, [*RUN, "--logdir", str(tmp_path / "runs"), "--wandb", "--wandb-project", project]
        )
        assert r.exit_code != 0 and "wandb project" in r.output and "Traceback" not in r.output
        assert not (tmp_path / "runs").exists()


def test_a_bad_wandb_mode_is_one_line(tmp_path, offline, monkeypatch):
    monkeypatch.setenv("WANDB_MODE", "bogus")
    with pytest.raises(ValueError, match="WANDB_MODE must be one of"):
        sc.evolve(
            scenario="one-niche", population=4, generations=1, logdir=tmp_path / "a", wandb="p"
        )
    assert not (tmp_path / "a").exists()


def test_wandb_that_cannot_start_is_one_warning_and_the_run_goes_on(tmp_path, offline, monkeypatch):
    """No network (CommError after a long wait) or any other failure of wandb.init: one warning
    line, and the run writes its own files in full."""
    import wandb

    def refuse(**kw):
        raise RuntimeError("CommError: network unreachable\n  many more lines")

    monkeypatch.setattr(wandb, "init", refuse)
    monkeypatch.chdir(tmp_path)
    with pytest.warns(
        RuntimeWarning, match="Weights & Biases logging stopped .*network unreachable"
    ):
        result = sc.evolve(
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
    assert json.loads((result.run_dir / "summary.json").read_text())["generation"] == 1
    assert not (tmp_path / "wandb").exists()
    with pytest.raises(ValueError, match="logdir"):
        sc.evolve(scenario="one-niche", population=4, generations=1, logdir=None, wandb="p")
