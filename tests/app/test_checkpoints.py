"""Reliability: checkpoints cannot run code, and damaged ones give one-line errors
(docs/RELIABILITY.md)."""

import io
from pathlib import Path

import pytest
import torch
from runkit import _copy_run, invoke, one_line_error, tiny_run

from swarmcode_torch.app.runs import RunError, load_checkpoint, read_checkpoint


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    return tiny_run(tmp_path_factory)


class Payload:
    """Unpickling this calls open(marker, 'w'): a file appears if the payload runs."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def _poison(run: Path, marker: Path, where: str) -> None:
    d = torch.load(run / "checkpoint.pt", weights_only=True)
    if where == "top":
        d["extra"] = Payload(marker)
    else:  # hidden deep inside the history records
        d["history"][0]["population"] = Payload(marker)
    buf = io.BytesIO()
    torch.save(d, buf)
    (run / "checkpoint.pt").write_bytes(buf.getvalue())


@pytest.mark.parametrize("where", ["top", "nested"])
def test_a_checkpoint_with_a_reduce_payload_is_refused_and_the_payload_never_runs(
    finished_run, tmp_path, where
):
    run = _copy_run(finished_run, tmp_path / "run")
    marker = tmp_path / "PWNED"
    _poison(run, marker, where)
    # the payload is real: an unrestricted unpickler runs it
    torch.load(run / "checkpoint.pt", weights_only=False)
    assert marker.exists()
    marker.unlink()

    with pytest.raises(RunError, match="would run code"):
        load_checkpoint(run)
    assert not marker.exists()
    r = invoke("evolve", "--resume", run, "--generations", 3)
    one_line_error(r, "would run code", "checkpoint.pt")
    assert not marker.exists()


def test_a_genuine_checkpoint_loads_with_only_plain_types(finished_run):
    d = load_checkpoint(finished_run)
    assert d["generation"] == 2 and isinstance(d["rng_state"], torch.Tensor)
    assert isinstance(d["config"], dict) and isinstance(d["history"], list)


@pytest.mark.parametrize(
    "damage", ["truncated", "garbage", "empty", "not-a-dict", "missing-key", "wrong-type"]
)
def test_a_damaged_checkpoint_is_a_one_line_error(finished_run, tmp_path, damage):
    run = _copy_run(finished_run, tmp_path / "run")
    path = run / "checkpoint.pt"
    data = path.read_bytes()
    if damage == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif damage == "garbage":
        path.write_bytes(b"\x80\x04not a checkpoint at all" * 10)
    elif damage == "empty":
        path.write_bytes(b"")
    else:
        d = torch.load(path, weights_only=True)
        if damage == "not-a-dict":
            d = [1, 2, 3]
        elif damage == "missing-key":
            del d["rng_state"]
        else:
            d["genome"] = "oops"
        buf = io.BytesIO()
        torch.save(d, buf)
        path.write_bytes(buf.getvalue())
    with pytest.raises(RunError):
        read_checkpoint(path)
    one_line_error(invoke("evolve", "--resume", run, "--generations", 3), "checkpoint")


def _old_layout(path: Path) -> dict:
    """The checkpoint at `path` rewritten as a version before the application's record moved out
    of the algorithm's state wrote it: "best" among the algorithm's entries, no "app" table;
    the new layout's contents."""
    d = torch.load(path, weights_only=True)
    old = {k: v for k, v in d.items() if k != "app"}
    old["best"] = d["app"]["best"]
    buf = io.BytesIO()
    torch.save(old, buf)
    path.write_bytes(buf.getvalue())
    return d


def test_a_checkpoint_holds_the_apps_record_beside_the_algorithms_state(finished_run):
    from swarmcode_torch.app.api import load
    from swarmcode_torch.app.runconfig import read_config
    from swarmcode_torch.coevo.evolve import Evolution

    d = torch.load(finished_run / "checkpoint.pt", weights_only=True)
    best = d["app"]["best"]
    assert set(d["app"]) == {"best"} and best["generation"] in (0, 1)
    assert "best" not in d  # the algorithm's state does not hold it
    algorithm = set(Evolution(read_config(finished_run)).state_dict())
    assert "best" not in algorithm and set(d) == algorithm | {"app", "run_files"}
    assert load(finished_run).best_team == best


def test_an_old_layout_checkpoint_reads_and_resumes_as_a_new_one(finished_run, tmp_path):
    from swarmcode_torch.app.api import load

    new = _copy_run(finished_run, tmp_path / "new")
    old = _copy_run(finished_run, tmp_path / "old")
    saved = _old_layout(old / "checkpoint.pt")
    assert "app" not in torch.load(old / "checkpoint.pt", weights_only=True)
    d = read_checkpoint(old / "checkpoint.pt")  # the record moved over on reading
    assert "best" not in d and d["app"] == saved["app"]
    assert load(old).best_team == load(new).best_team == saved["app"]["best"]
    assert invoke("inspect", old).exit_code == 0
    for run in (new, old):
        r = invoke("evolve", "--resume", run, "--generations", 4)
        assert r.exit_code == 0, r.output
    assert (old / "teams.jsonl").read_bytes() == (new / "teams.jsonl").read_bytes()
    a, b = load_checkpoint(old), load_checkpoint(new)
    assert a["generation"] == b["generation"] == 4 and a["app"] == b["app"]
    assert a["history"] == b["history"] and torch.equal(a["rng_state"], b["rng_state"])
    assert all(torch.equal(a["genome"][k], b["genome"][k]) for k in a["genome"])
    # the resume wrote the new layout
    assert "best" not in torch.load(old / "checkpoint.pt", weights_only=True)


def test_an_old_layout_checkpoint_branches(finished_run, tmp_path):
    old = _copy_run(finished_run, tmp_path / "old")
    _old_layout(old / "checkpoint.pt")
    logdir = tmp_path / "runs"
    r = invoke("evolve", "--from", old, "--generations", 3, "--logdir", logdir)
    assert r.exit_code == 0, r.output
    (branch,) = list(logdir.iterdir())
    assert load_checkpoint(branch)["generation"] == 3


@pytest.mark.parametrize(
    "edit,needle",
    [
        (lambda d: d.__setitem__("app", [1]), "'app' has the wrong type (list)"),
        (lambda d: d.__setitem__("app", {}), "no 'app.best'"),
        (lambda d: d["app"].__setitem__("best", 5), "'app.best' has the wrong type (int)"),
        (lambda d: d["app"]["best"].__setitem__("fitness", "high"), "app.best.fitness"),
        (lambda d: d.pop("app"), "no 'app'"),
        # an old layout's record, damaged: named where it lies in the file
        (lambda d: d.__setitem__("best", dict(d.pop("app")["best"], fitness="x")), ": best.fit"),
        (lambda d: d.__setitem__("best", d.pop("app") and 7), "'best' has the wrong type (int)"),
    ],
)
def test_a_damaged_app_record_is_a_one_line_error(finished_run, tmp_path, edit, needle):
    run = _copy_run(finished_run, tmp_path / "run")
    path = run / "checkpoint.pt"
    d = torch.load(path, weights_only=True)
    edit(d)
    buf = io.BytesIO()
    torch.save(d, buf)
    path.write_bytes(buf.getvalue())
    with pytest.raises(RunError, match="checkpoint.pt"):
        read_checkpoint(path)
    one_line_error(invoke("evolve", "--resume", run, "--generations", 3), needle)
