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
