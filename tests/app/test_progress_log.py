"""Progress off a terminal (a log file, Slurm, nohup): every plain progress line of evolve and
of a sweep says the elapsed and the remaining time (`eta`), counted from where this process
started."""

import re
import sys
from types import SimpleNamespace

import pytest
from test_api import SETTINGS
from test_cli import TINY, invoke

import swarmcode_torch as sc
from swarmcode_torch.app import terminal
from swarmcode_torch.app.eta import Eta, clock

#: 'elapsed 12s, left ~1m05s' (left ? before an estimate, left 0s at the end)
TIMES = r"elapsed (\d+[smhd]|\d+m\d\ds|\d+h\d\dm|\d+d\d\dh), left (\?|0s|~\S+)"


@pytest.mark.parametrize(
    ("seconds", "text"),
    [(0, "0s"), (59.4, "59s"), (60, "1m00s"), (3599, "59m59s"), (3600, "1h00m"), (90061, "1d01h")],
)
def test_clock(seconds, text):
    assert clock(seconds) == text


def test_eta_counts_from_this_process_at_the_rate_so_far():
    t = [100.0]
    eta = Eta(10, start=5, now=lambda: t[0])  # a run resumed after 5 of 10 generations
    assert eta.text(5) == "elapsed 0s, left ?"
    t[0] += 4.0
    assert eta.left(7) == pytest.approx(6.0)  # 2 generations in 4 s: 3 more in 6 s
    assert eta.text(7) == "elapsed 4s, left ~6s"
    t[0] += 300.0
    assert eta.text(10) == "elapsed 5m04s, left 0s"


def test_plain_progress_lines_carry_the_times(monkeypatch, capsys):
    monkeypatch.setattr(terminal.sys.stdout, "isatty", lambda: False)
    t = [0.0]
    rep = terminal.ProgressReporter(4, 0, 1)
    rep.eta = Eta(4, now=lambda: t[0])
    team = {"fitness": 1.0, "species": 1, "niches": 1, "cost": 10.0}
    for g in range(4):
        t[0] += 30.0
        ev = SimpleNamespace(
            state=SimpleNamespace(generation=g + 1), cfg=SimpleNamespace(generations=4), done=g == 3
        )
        r = SimpleNamespace(
            generation=g, team=team, best={"fitness": 1.0}, num_species=1, seconds=30.0
        )
        rep.on_generation(ev, r)
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split("  generation")[0] for ln in lines] == [
        "done 1/4  elapsed 30s, left ~1m30s",
        "done 2/4  elapsed 1m00s, left ~1m00s",
        "done 3/4  elapsed 1m30s, left ~30s",
        "done 4/4  elapsed 2m00s, left 0s",
    ]


def _progress(output: str) -> list[str]:
    return [ln for ln in output.splitlines() if ln.startswith("done ")]


def test_evolve_logs_times_on_every_line(tmp_path):
    r = invoke("evolve", *TINY, "--generations", 3, "--log-every", 1, "--logdir", tmp_path)
    assert r.exit_code == 0, r.output
    lines = _progress(r.output)
    assert [ln.split("  ")[0] for ln in lines] == ["done 1/3", "done 2/3", "done 3/3"]
    for ln in lines:
        assert re.match(rf"done \d/3  {TIMES}  generation \d ", ln), ln
    assert lines[-1].split("  ")[1].endswith("left 0s")


def test_a_sweep_logs_times_on_every_line(tmp_path):
    sweep = [
        "sweep",
        *TINY[:-2],
        "--device",
        "cpu",
        "--no-compile",
        "--generations",
        2,
        "--budgets",
        "300,600",
        "--log-every",
        1,
    ]
    r = invoke(*sweep, "--out", tmp_path / "s")
    assert r.exit_code == 0, r.output
    lines = _progress(r.output)
    assert len(lines) == 4 and all(re.search(TIMES, ln) for ln in lines), r.output
    ends = [ln for ln in r.output.splitlines() if ": finished (" in ln]
    assert len(ends) == 2, r.output
    assert re.fullmatch(rf"budget-300_seed-0: finished \(1 of 2 runs\)  {TIMES}", ends[0])
    assert ends[1].startswith("budget-600_seed-0: finished (2 of 2 runs)")
    assert ends[1].endswith("left 0s")


def test_progress_true_prints_a_line_per_generation_and_false_prints_nothing(tmp_path, capsys):
    capsys.readouterr()
    sc.evolve(generations=2, logdir=None, progress=True, **SETTINGS)
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split("  ")[0] for ln in lines] == ["done 1/2", "done 2/2"], lines
    assert all(" left " in ln and " best " in ln and " species " in ln for ln in lines), lines
    run = sc.evolve(generations=1, logdir=tmp_path, render_every=0, progress=False, **SETTINGS)
    sc.resume(run.run_dir, generations=2, render_every=0, progress=False)
    assert capsys.readouterr() == ("", "")
    sc.resume(run.run_dir, generations=3, render_every=0, progress=True)
    assert [ln.split("  ")[0] for ln in capsys.readouterr().out.splitlines()] == ["done 3/3"]
    sc.evolve(generations=1, logdir=None, **SETTINGS)  # the default: not on a pipe or file
    assert capsys.readouterr() == ("", "")
    with pytest.raises(TypeError, match="progress"):
        sc.evolve(generations=1, logdir=None, progress="yes", **SETTINGS)


def test_progress_on_a_terminal_or_in_a_notebook_is_one_line_redrawn(monkeypatch):
    import io

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    screen = Terminal()
    monkeypatch.setattr(sys, "stdout", screen)
    sc.evolve(generations=3, logdir=None, **SETTINGS)  # the default shows it here
    text = screen.getvalue()
    assert text.endswith("\n") and text.count("\n") == 1, repr(text)
    frames = text.rstrip("\n").split("\r")[1:]
    assert [f.split("  ")[0] for f in frames] == ["done 1/3", "done 2/3", "done 3/3"], frames
