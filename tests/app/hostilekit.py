"""What the hostile-input tests of tests/app share: a tiny run's options, the CLI runner, the
one-line-error check (on stderr; it returns the line), `tiny_run`, the two-generation run
that each test module's module-scoped `finished_run` fixture makes, and a snapshot of a
run's files."""

from __future__ import annotations

from pathlib import Path

from runkit import TINY as RUN_TINY
from runkit import runner

from swarmcode_torch.app.cli import app

#: runkit's tiny run, without replay images or compiling, on the CPU
TINY = [*RUN_TINY, "--render-every", "0", "--no-compile", "--device", "cpu"]
RFAST = ["--render-every", "0", "--device", "cpu"]


def invoke(*args, **kw):
    return runner.invoke(app, [str(a) for a in args], **kw)


def one_line_error(result, *needles):
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, result.output
    assert lines[0].startswith("Error: "), result.output
    for n in needles:
        assert n in lines[0], result.output
    return lines[0]


def tiny_run(tmp_path_factory) -> Path:
    """A finished two-generation run of TINY: what the `finished_run` fixtures return."""
    logdir = tmp_path_factory.mktemp("runs")
    r = invoke("evolve", *TINY, "--generations", 2, "--logdir", logdir)
    assert r.exit_code == 0, r.output
    (run,) = list(logdir.iterdir())
    return run


def _snapshot(run: Path) -> dict[str, bytes]:
    return {f.name: f.read_bytes() for f in run.iterdir() if f.is_file() and not f.is_symlink()}
