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
