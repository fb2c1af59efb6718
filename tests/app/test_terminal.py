"""What the command line prints, as a terminal or a log shows it: the progress line fitted to
the window, and commands and paths never wrapped."""

from __future__ import annotations

import io
import re
import subprocess
import sys
from types import SimpleNamespace

import pytest
from rich.console import Console

from swarmcode_torch.app import terminal


def _generation(g: int, total: int):
    """An (Evolution, GenerationResult) pair as the progress reporter reads them."""
    team = {"fitness": 120.25, "species": 3, "niches": 2, "cost": 3950.0}
    ev = SimpleNamespace(
        state=SimpleNamespace(generation=g + 1),
        cfg=SimpleNamespace(generations=total),
        done=g + 1 == total,
    )
    r = SimpleNamespace(
        generation=g, team=team, best={"fitness": 123.5}, num_species=7, seconds=1.25
    )
    return ev, r


def _progress_lines(monkeypatch, columns: int) -> list[str]:
    """The progress line of generation 1 of 3 (2 done) on a terminal of `columns` columns (the
    COLUMNS a shell sets), as the screen shows it when the display stops."""
    monkeypatch.setenv("COLUMNS", str(columns))
    monkeypatch.delenv("LINES", raising=False)
    screen = io.StringIO()
    out = Console(file=screen, force_terminal=True, color_system=None)
    assert out.width == columns
    monkeypatch.setattr(terminal, "console", out)
    monkeypatch.setattr(terminal.sys.stdout, "isatty", lambda: True)
    rep = terminal.ProgressReporter(3, 0, 1)
    ev, r = _generation(0, 3)
    rep.on_start(ev)
    rep.on_generation(ev, r)
    ev, r = _generation(1, 3)
    rep.on_generation(ev, r)
    rep.stop()
    # each refresh redraws the line (carriage return, erase line); the last one stays on screen
    text = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", screen.getvalue())
    return [ln.rstrip() for ln in re.split(r"[\r\n]", text) if ln.strip()]


@pytest.mark.parametrize("columns", [80, 40])
def test_the_progress_line_fits_the_window_with_the_count_and_time_left_first(monkeypatch, columns):
    lines = _progress_lines(monkeypatch, columns)
    assert lines, "no progress line"
    last = lines[-1]
    assert all(len(ln) <= columns for ln in lines), lines
    assert last.startswith("done 2/3 left "), lines  # the essential fields, in view
    assert "generation 1" in last or last.endswith("…"), lines


def test_a_wide_window_shows_the_bar_and_every_figure(monkeypatch):
    last = _progress_lines(monkeypatch, 200)[-1]
    assert last.startswith("done 2/3 left ") and "━" in last
    assert "generation 1  best team 123.5" in last and "1.25s/gen" in last


@pytest.mark.subprocess
def test_commands_and_paths_are_never_wrapped_off_a_terminal(tmp_path):
    # a log (stdout a pipe) is 120 columns wide; a long --logdir must still print whole
    logdir = tmp_path / ("a-long-directory-name-" * 4) / ("and-another-one-" * 4)
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "swarmcode_torch",
            "evolve",
            "--scenario",
            "one-niche",
            "--population",
            "6",
            "--swarm-size",
            "4",
            "--trials",
            "1",
            "--ticks",
            "8",
            "--generations",
            "1",
            "--render-every",
            "0",
            "--device",
            "cpu",
            "--no-compile",
            "--threads",
            "1",
            "--logdir",
            str(logdir),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    (run,) = list(logdir.iterdir())
    assert len(str(run)) > 120  # longer than the log's width
    lines = r.stdout.splitlines()
    assert f"Watch: tensorboard --logdir {logdir}" in lines, r.stdout
    assert f"Inspect: swarmcode-torch inspect {run}" in lines, r.stdout
    assert any(ln.startswith(f"Run directory: {run}  (device cpu") for ln in lines), r.stdout
    assert any(ln.startswith(f"Done: 1 generations in {run}") for ln in lines), r.stdout
