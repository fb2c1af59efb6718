"""Table III aggregation from run summaries."""

import json

import torch
from runkit import invoke, one_line_error

from swarmcode_torch.app.sweep import csv_text, markdown, table_rows
from swarmcode_torch.coevo.population import Population, design_record

_POP = Population.random(1, 16, 8, torch.Generator().manual_seed(0), torch.device("cpu"))
DESIGN = dict(design_record(_POP, 0, species=0, cost=500.0), count=4)


def _summary(d, **kw):
    base = dict(
        best_fitness=100.0,
        team_cost=2500.0,
        deliveries=4.0,
        deliveries_individual=4.0,
        deliveries_collab=0.0,
        energy_used=50.0,
        num_species=1,
        best_generation=0,
        budget=None,
        designs=[DESIGN],
    )
    base.update(kw)
    d.mkdir()
    (d / "summary.json").write_text(json.dumps(base))
    return d


def test_rows_average_seeds_per_budget(tmp_path):
    runs = [
        (3000.0, 0, _summary(tmp_path / "a", best_fitness=100.0, num_species=1)),
        (3000.0, 1, _summary(tmp_path / "b", best_fitness=200.0, num_species=3)),
        (2500.0, 0, _summary(tmp_path / "c", best_fitness=50.0)),
    ]
    rows = table_rows(runs)
    assert [r["budget"] for r in rows] == [2500.0, 3000.0]
    # the sample standard deviation over seeds, as in every table (dynamics.mean_std)
    assert rows[1]["best_fitness"] == 150.0 and rows[1]["best_fitness_std"] == 50.0 * 2**0.5
    assert rows[1]["num_species"] == 2.0 and rows[1]["seeds"] == 2
    md = markdown(rows)
    assert "| 3000 | 150.0 ± 70.7 |" in md
    assert csv_text(rows).splitlines()[0].startswith("budget,seeds,best_fitness,best_fitness_std")


def test_budget_plot_shows_fitness_and_species_apart_with_integer_species_ticks(
    tmp_path, monkeypatch
):
    # fitness and species that would coincide exactly on twin axes (same shape, same limits)
    from matplotlib.figure import Figure

    from swarmcode_torch.app.sweep import plot

    rows = [
        dict(
            budget=b,
            best_fitness=float(s),
            best_fitness_std=0.0,
            num_species=s,
            num_species_std=0.0,
        )
        for b, s in ((2500.0, 1), (4000.0, 2), (6000.0, 3))
    ]
    drawn = []
    real = Figure.savefig
    monkeypatch.setattr(
        Figure, "savefig", lambda self, *a, **k: (drawn.append(self), real(self, *a, **k))[1]
    )
    plot(rows, tmp_path / "budget.png")
    (fig,) = drawn
    assert (tmp_path / "budget.png").stat().st_size > 0
    fig.canvas.draw()
    axes = fig.get_axes()
    assert len(axes) == 2
    boxes = [ax.get_position() for ax in axes]
    assert not boxes[0].overlaps(boxes[1]), boxes  # two panels, not twin axes
    assert axes[0].get_shared_x_axes().joined(axes[0], axes[1])  # one budget axis
    ys = [
        [list(line.get_ydata()) for line in ax.get_lines() if len(line.get_ydata()) == 3]
        for ax in axes
    ]
    assert [1.0, 2.0, 3.0] in ys[0] and [1, 2, 3] in ys[1]  # each panel has its own line
    assert "fitness" in axes[0].get_ylabel() and "species" in axes[1].get_ylabel()
    lo, hi = axes[1].get_ylim()
    ticks = [t for t in axes[1].get_yticks() if lo <= t <= hi]
    assert ticks and all(float(t).is_integer() for t in ticks), ticks


# ====================================================================== sweeps
SWEEP = [
    "sweep",
    "--budgets",
    "1500",
    "--seeds",
    "0",
    "--scenario",
    "one-niche",
    "--generations",
    1,
    "--population",
    6,
    "--swarm-size",
    4,
    "--trials",
    1,
    "--ticks",
    10,
    "--device",
    "cpu",
    "--no-compile",
]


def test_a_sweep_into_an_out_of_other_settings_is_refused(tmp_path):
    out = tmp_path / "sweep"
    r = invoke(*SWEEP, "--out", out)
    assert r.exit_code == 0, r.output
    for change, keys in (
        ((("--population", 6), ("--population", 8)), "population"),
        ((("--trials", 1), ("--trials", 2)), "trials"),
        ((("--ticks", 10), ("--ticks", 12)), "ticks"),
        ((("--scenario", "one-niche"), ("--scenario", "two-niche")), "scenario"),
    ):
        args = list(SWEEP)
        i = args.index(change[0][0])
        args[i + 1] = change[1][1]
        one_line_error(invoke(*args, "--out", out), "other settings", f"differing keys: {keys}")
    one_line_error(invoke(*SWEEP, "--objective", "roi", "--out", out), "differing keys: objective")
    one_line_error(
        invoke(*SWEEP, "--set", "delta=0.5", "--set", "p_tag_flip=0.5", "--out", out),
        "differing keys: delta, p_tag_flip",
    )
    r = invoke(*SWEEP, "--out", out)  # the same sweep: already done
    assert r.exit_code == 0 and "already done" in r.output, r.output


def test_a_sweep_refuses_duplicated_or_non_finite_budgets_and_seeds(tmp_path):
    one_line_error(
        invoke("sweep", "--budgets", "1500,3000,1500", "--out", tmp_path / "a"),
        "--budgets lists 1500 twice",
    )
    one_line_error(
        invoke("sweep", "--seeds", "0,1,0", "--out", tmp_path / "a"), "--seeds lists 0 twice"
    )
    one_line_error(
        invoke("sweep", "--budgets", "1500,nan", "--out", tmp_path / "a"),
        "--budgets: nan is not a finite number",
    )
    one_line_error(
        invoke("sweep", "--seeds", str(2**64), "--out", tmp_path / "a"),
        "--seeds must be in [0, 9223372036854775807]",
    )
    assert not (tmp_path / "a").exists()


def test_a_sweep_table_from_a_damaged_summary_is_one_line(tmp_path):
    out = tmp_path / "sweep"
    assert invoke(*SWEEP, "--out", out).exit_code == 0
    summary = out / "budget-1500_seed-0" / "summary.json"
    summary.write_text(summary.read_text().replace('"team_cost": ', '"team_cost": "x", "y": '))
    one_line_error(
        invoke(*SWEEP, "--out", out), str(summary), "team_cost: expected a number", stdout_ok=True
    )
