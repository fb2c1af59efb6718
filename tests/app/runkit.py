"""What the reliability tests of tests/app share: a tiny run's options, the CLI runner, the
one-line-error check, the copy of a run directory, a custom scenario (`MINE`) and its file, the
check of a full disk's message, and `tiny_run`, the two-generation run that each test module's
module-scoped `finished_run` fixture makes."""

from pathlib import Path

from typer.testing import CliRunner

from swarmcode_torch.app.cli import app
from swarmcode_torch.app.runs import LOCK_FILE, load_checkpoint

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
    "10",
    "--seed",
    "3",
]


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def one_line_error(result, *needles, stdout_ok: bool = False):
    """Exit 2, no traceback, and the error is one line (on stderr; with `stdout_ok`, what the
    run printed before it failed is allowed on stdout)."""
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    text = result.stderr if stdout_ok else result.output
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, result.output
    assert lines[0].startswith("Error: "), result.output
    for n in needles:
        assert n in lines[0], result.output


def tiny_run(tmp_path_factory) -> Path:
    """A finished two-generation run of TINY: what the `finished_run` fixtures return."""
    logdir = tmp_path_factory.mktemp("runs")
    r = invoke("evolve", *TINY, "--generations", 2, "--logdir", logdir)
    assert r.exit_code == 0, r.output
    (run,) = list(logdir.iterdir())
    return run


def _copy_run(run: Path, to: Path) -> Path:
    to.mkdir()
    for f in run.iterdir():
        if f.is_file():
            (to / f.name).write_bytes(f.read_bytes())
    return to


FAST = ["--render-every", "0", "--no-compile", "--device", "cpu"]
RFAST = ["--render-every", "0", "--device", "cpu"]  # what --resume may be given
REPO = Path(__file__).resolve().parents[2]


def _full_disk_line(r, run: Path, generation: int):
    last = (
        f"last checkpoint after generation {generation - 1} "
        if generation
        else "last checkpoint before generation 0 "
    )
    one_line_error(
        r, "No space left on device", last, f"swarmcode-torch evolve --resume {run}", stdout_ok=True
    )
    assert load_checkpoint(run)["generation"] == generation  # the previous one, intact
    assert not list(run.glob(".checkpoint.pt.*")) and not list(run.glob(".summary.json.*"))
    assert not (run / LOCK_FILE).exists()


MINE = """name = "mine"
description = "a custom world"
arena = 14.0
base_radius = 1.0
num_robots = 4
episode_ticks = 10

[[packages]]
kind = "individual"
effector = "pincher"
count = 3
distance = [2.5, 5.0]
mass = [1.0, 3.0]
"""


def _scenario(tmp_path: Path, text: str, name="s.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path
