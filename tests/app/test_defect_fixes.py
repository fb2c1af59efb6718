"""Small defects, each shown fixed: whole-number ticks on the integer axes of budget.png, stop
lines that number generations as summary.json does, branch runs named as branches."""

import io

import pytest

from swarmcode_torch.app import sweep


def _drawn_axes(rows, monkeypatch):
    from matplotlib.figure import Figure

    drawn = []
    real = Figure.savefig
    monkeypatch.setattr(
        Figure, "savefig", lambda self, *a, **k: (drawn.append(self), real(self, *a, **k))[1]
    )
    sweep.plot(rows, io.BytesIO())
    (fig,) = drawn
    fig.canvas.draw()
    return fig.get_axes()


def _visible_ticks(ticks, lim) -> list[float]:
    lo, hi = sorted(lim)
    return [float(t) for t in ticks if lo - 1e-9 <= t <= hi + 1e-9]


def _row(budget, species, species_std=0.0):
    return dict(
        budget=budget,
        best_fitness=10.0,
        best_fitness_std=1.0,
        num_species=species,
        num_species_std=species_std,
    )


@pytest.mark.parametrize(
    "rows",
    [
        [_row(3000.0, 3.0)],  # one budget, one species count: both axes span < 2 integers
        [_row(300.0, 2.0), _row(301.0, 2.5, 0.2)],  # budgets $1 apart, species 2-2.7
        [_row(2500.0, 1.0), _row(4000.0, 2.0), _row(6000.0, 4.0, 1.0)],
    ],
)
def test_budget_plot_ticks_only_whole_species_and_budgets(rows, monkeypatch):
    fit_ax, species_ax = _drawn_axes(rows, monkeypatch)
    ys = _visible_ticks(species_ax.get_yticks(), species_ax.get_ylim())
    xs = _visible_ticks(species_ax.get_xticks(), species_ax.get_xlim())
    assert ys and all(y == int(y) for y in ys), ys
    assert xs and all(x == int(x) for x in xs), xs
    labels = [t.get_text() for t in species_ax.get_yticklabels() if t.get_text()]
    assert labels and not any("." in s for s in labels), labels


def test_budgets_with_cents_keep_matplotlib_ticks(monkeypatch):
    fit_ax, species_ax = _drawn_axes([_row(2500.5, 2.0), _row(2501.0, 3.0)], monkeypatch)
    xs = _visible_ticks(species_ax.get_xticks(), species_ax.get_xlim())
    assert any(x != int(x) for x in xs), xs  # the budget axis is not forced to whole dollars


def test_stop_lines_count_generations_and_number_them_from_0(monkeypatch, tmp_path):
    """A run stopped by --max-time: the line counts the generations that finished and numbers
    them as summary.json and teams.jsonl do (from 0); inspect says the same."""
    import json
    import re

    from test_cli import TINY, invoke
    from test_workflow import FakeClock

    from swarmcode_torch.app import session, terminal

    monkeypatch.setattr(session, "clock", FakeClock())  # 10 s a generation: 3 in 30 s
    r = invoke("evolve", *TINY, "--generations", 5, "--max-time", "30s", "--logdir", tmp_path)
    assert r.exit_code == 0, r.output
    (run,) = tmp_path.iterdir()
    text = " ".join(r.output.split())
    m = re.search(r"Stopped after (\d+) generations \(0-(\d+)\): --max-time reached", text)
    assert m, text
    summary = json.loads((run / "summary.json").read_text())
    numbers = [json.loads(ln)["generation"] for ln in (run / "teams.jsonl").open()]
    assert int(m[1]) == len(numbers) == summary["stop"]["generation"]  # the count
    assert int(m[2]) == summary["generation"] == numbers[-1]  # the last one's number
    r = invoke("inspect", run)
    assert r.exit_code == 0, r.output
    assert f"Stopped early by max_time after {m[1]} generations (0-{m[2]})" in r.output
    assert terminal.generations_done(1) == "1 generation (generation 0)"
    assert terminal.generations_done(0) == "no generation"


def test_branch_directory_is_named_after_its_parent(tmp_path):
    """A branch's directory (`--from RUN@G`, `sc.evolve(from_run=...)`) starts with its
    parent's name and says where it branched: PARENT__branch-gG__TIME; a fresh run's does not."""
    import json
    import re
    from types import SimpleNamespace

    from test_workflow import new_run

    import swarmcode_torch as sc
    from swarmcode_torch.app.files import MAX_PARENT_NAME, branch_dir_name, new_run_dir

    parent = new_run(tmp_path / "runs", "--generations", 3, "--snapshot-every", 2)
    assert "__branch-" not in parent.name
    child = new_run(
        tmp_path / "runs", "--from", f"{parent}@2", "--generations", 4, "--snapshot-every", 2
    )
    assert re.fullmatch(re.escape(parent.name) + r"__branch-g2__\d{8}-\d{6}", child.name)
    assert json.loads((child / "summary.json").read_text())["parent"]["generation"] == 2
    api = sc.evolve(from_run=f"{child}@4", logdir=tmp_path / "api", generations=5)
    assert api.run_dir.name.startswith(child.name + "__branch-g4__")
    # a long chain of branches keeps a valid name; two at the same second get -1
    long = SimpleNamespace(run_dir=tmp_path / ("x" * 240), generation=7)
    made = [new_run_dir(tmp_path / "chain", None, long) for _ in range(2)]
    assert made[0].name.startswith("x" * MAX_PARENT_NAME + "__branch-g7__")
    assert made[1].name == made[0].name + "-1" and len(made[0].name) < 200
    assert branch_dir_name(parent, 5, when=0).startswith(parent.name + "__branch-g5__")
