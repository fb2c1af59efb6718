"""Budget sweeps: one evolution per (budget, seed), summarised as the paper's Table III: which
runs a sweep has to start, resume or leave (`plan_run`), and the table of their summaries."""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

from ..coevo.config import SwarmCoDeConfig
from ..coevo.dynamics import mean_std
from ..sim.scenario import Scenario
from .checkpoints import load_checkpoint, load_run
from .files import (
    BUDGET_PLOT,
    CHECKPOINT_FILE,
    CONFIG_FILE,
    SCENARIO_COPY,
    SUMMARY_FILE,
    TABLE_CSV,
    TABLE_MD,
    RunError,
    atomic_write_bytes,
    read_text,
)
from .runconfig import config_differences, read_config, run_scenario
from .summary import TEAM_FIGURES, read_summary

COLUMNS = ("budget", *TEAM_FIGURES)
HEADERS = (
    "Budget",
    "Best fitness",
    "Team cost",
    "Total deliveries",
    "Individual",
    "Collaborative",
    "Avg. energy used",
    "# species",
)


def run_name(budget: float | None, seed: int) -> str:
    b = "none" if budget is None else f"{budget:g}"
    return f"budget-{b}_seed-{seed}"


#: Config keys that say how a run runs, not what it computes: a sweep run again with other
#: values of these resumes its runs with their saved ones.
HOW_KEYS = ("generations", "device", "compile", "cuda_graphs")


@dataclass(frozen=True)
class PlannedRun:
    """One run of a sweep: where it is, its config and what the sweep does with it ('new',
    'resume' or 'done'; `done`: the generations its checkpoint has)."""

    budget: float | None
    seed: int
    run_dir: Path
    cfg: SwarmCoDeConfig
    state: str
    done: int | None = None


def plan_run(out: Path, cfg: SwarmCoDeConfig, scenario: Scenario, prefix: str = "") -> PlannedRun:
    """What the sweep in `out` does with its run of `cfg`: start it, resume it from its
    checkpoint, or leave it (done). RunError for an existing run whose config differs from this
    sweep's in anything but how it runs (`HOW_KEYS`); OSError, ScenarioError, RunError for a
    run directory that cannot be read. `prefix`: the grid point's part of the run's name
    (`sweep_grid.point_name`)."""
    run_dir = Path(out) / (prefix + run_name(cfg.budget, cfg.seed))

    def planned(state: str, done: int | None = None) -> PlannedRun:
        return PlannedRun(cfg.budget, cfg.seed, run_dir, cfg, state, done)

    if not (run_dir / CONFIG_FILE).is_file():
        return planned("new")
    has_checkpoint = (run_dir / CHECKPOINT_FILE).is_file()
    saved = load_run(run_dir)[0] if has_checkpoint else read_config(run_dir)
    diff = config_differences(saved, cfg, scenario, ignore=HOW_KEYS)
    if (
        "scenario" not in diff
        and (run_dir / SCENARIO_COPY).is_file()
        and run_scenario(run_dir, saved) != scenario
    ):
        diff.append("scenario (the file's content)")
    if diff:
        raise RunError(
            f"{run_dir} holds a run with other settings than this sweep's (differing "
            f"keys: {', '.join(diff)}); use another --out, or the options it was run "
            "with"
        )
    if not has_checkpoint:
        return planned("new")
    done = load_checkpoint(run_dir)["generation"]
    return planned("done" if done >= cfg.generations else "resume", done)


@dataclass(frozen=True)
class SweepContents:
    """A sweep directory as it stands: its table (table.md's text; None before the sweep has
    written one) and its runs, each (name, generations recorded, generations asked for; None
    where its summary.json is missing or cannot be read)."""

    table: str | None
    runs: list[tuple[str, int | None, int | None]]


def sweep_contents(path: Path) -> SweepContents | None:
    """The table and runs of the sweep directory `path`; None when it is no sweep directory (a
    run directory, or a directory with neither a table nor runs). RunError for a table that
    cannot be read."""
    path = Path(path)
    if (path / CONFIG_FILE).exists() or (path / SUMMARY_FILE).exists():
        return None  # a run directory
    runs = []
    for d in sorted(p for p in path.iterdir() if p.is_dir() and not p.is_symlink()):
        if not (d / CONFIG_FILE).is_file():
            continue
        try:
            s = read_summary(d, figures=False)
            done = s.get("generation")
            total = s.get("generations")
            runs.append(
                (
                    d.name,
                    done + 1 if isinstance(done, int) else None,
                    total if isinstance(total, int) else None,
                )
            )
        except RunError:
            runs.append((d.name, None, None))
    has_table = (path / TABLE_MD).is_file()
    if not runs and not has_table:
        return None
    return SweepContents(read_text(path / TABLE_MD) if has_table else None, runs)


def table_rows(runs: list[tuple], keys: tuple[str, ...] = ()) -> list[dict]:
    """One row per budget (and grid point: `keys`, the grid's settings, each run
    (budget, seed, run directory, {key: value})): each column's mean over seeds and its
    sample standard deviation (`<col>_std`, 0 for one seed; `dynamics.mean_std`)."""
    by_point: dict = {}
    for budget, _seed, run_dir, *point in runs:
        values = tuple(point[0][k] for k in keys) if keys else ()
        by_point.setdefault((values, budget), []).append(read_summary(run_dir))
    rows = []
    for (values, budget), summaries in by_point.items():
        row = {**dict(zip(keys, values)), "budget": budget, "seeds": len(summaries)}
        for col in COLUMNS[1:]:
            # a figure a run could not give (null in summary.json: not finite) is left out of
            # the mean; a column no run gives is "none"
            vals = [float(s[col]) for s in summaries if s.get(col) is not None]
            row[col], row[f"{col}_std"] = mean_std(vals) if vals else (None, None)
        row.update(_interval(summaries))
        rows.append(row)
    order = [*keys, "budget"]
    rows.sort(key=lambda r: tuple(_order(r[k]) for k in order))
    return rows


def _order(v) -> tuple:
    """A sort key of a setting's value: numbers in order, then text, None last."""
    if v is None:
        return (2, math.inf, "")
    if isinstance(v, (int, float)):
        return (0, float(v), "")
    return (1, 0.0, str(v))


def _interval(summaries: list[dict]) -> dict:
    """The runs' best-team re-evaluation (`best_team`): the fresh environments each best team
    was re-evaluated on (the fewest of the runs; None where a run was not re-evaluated), the
    mean of the bounds of their 95 % intervals and of their half-widths (None without)."""
    ks = [s.get("best_reeval_trials") for s in summaries]
    cis = [s.get("best_fitness_ci95") for s in summaries]
    cis = [c for c in cis if isinstance(c, list) and len(c) == 2 and None not in c]
    k = min(ks) if all(isinstance(x, int) and x > 0 for x in ks) else None
    if k is None or len(cis) < len(summaries):
        return {
            "best_reeval_trials": k,
            "best_fitness_ci_lo": None,
            "best_fitness_ci_hi": None,
            "best_fitness_ci_half": None,
        }
    n = len(cis)
    return {
        "best_reeval_trials": k,
        "best_fitness_ci_lo": sum(c[0] for c in cis) / n,
        "best_fitness_ci_hi": sum(c[1] for c in cis) / n,
        "best_fitness_ci_half": sum((c[1] - c[0]) / 2 for c in cis) / n,
    }


#: The columns of table.csv after the figures: the best teams' re-evaluation (`_interval`).
INTERVAL_COLUMNS = (
    "best_reeval_trials",
    "best_fitness_ci_lo",
    "best_fitness_ci_hi",
    "best_fitness_ci_half",
)


def _fmt(v, col: str) -> str:
    if v is None:
        return "none"
    if col in ("budget", "team_cost"):
        return f"{v:.0f}"
    return f"{v:.1f}" if col != "num_species" else f"{v:.2g}"


def _setting(v) -> str:
    return "none" if v is None else f"{v:g}" if isinstance(v, float) else str(v)


def markdown(rows: list[dict], keys: tuple[str, ...] = ()) -> str:
    """Table III (`keys`: the grid's settings, a column each before the budget)."""
    seeds = max((r["seeds"] for r in rows), default=1)
    headers = (*keys, *HEADERS)
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    for r in rows:
        cells = [_setting(r[k]) for k in keys]
        for col in COLUMNS:
            cell = _fmt(r[col], col)
            if seeds > 1 and col != "budget":
                cell += f" ± {_fmt(r[col + '_std'], col)}"
            if col == "best_fitness" and r.get("best_fitness_ci_half") is not None:
                if r["seeds"] > 1:
                    cell += f" (CI ± {_fmt(r['best_fitness_ci_half'], col)})"
                else:
                    lo, hi = r["best_fitness_ci_lo"], r["best_fitness_ci_hi"]
                    cell += f" [{_fmt(lo, col)}, {_fmt(hi, col)}]"
            cells.append(cell)
        lines.append("| " + " | ".join(cells) + " |")
    note = (
        f"\nMean over {seeds} seeds (± std); the best team of each run."
        if seeds > 1
        else "\nThe best team of each run."
    )
    ks = {r.get("best_reeval_trials") for r in rows if r.get("best_fitness_ci_half") is not None}
    if ks:
        k = min(ks)
        note += (
            f" Best fitness: the best team's mean over {k} fresh environments it was "
            "re-evaluated on, "
            + (
                "with the mean half-width of the runs' 95 % intervals (CI ±)."
                if seeds > 1
                else "with its 95 % interval [low, high]."
            )
        )
    return "\n".join(lines) + "\n" + note + "\n"


def csv_text(rows: list[dict], keys: tuple[str, ...] = ()) -> str:
    buf = io.StringIO()
    fields = [*keys, "budget", "seeds"] + [c for col in COLUMNS[1:] for c in (col, f"{col}_std")]
    fields += INTERVAL_COLUMNS
    w = csv.DictWriter(buf, fieldnames=fields)
    w.writeheader()
    for r in rows:
        w.writerow({k: ("none" if r.get(k) is None else r[k]) for k in fields})
    return buf.getvalue()


def _whole_ticks():
    """A tick locator of whole numbers only: matplotlib's MaxNLocator(integer=True) ticks
    fractions on an axis that spans less than two integers; this keeps the whole ones (the
    nearest to the middle when there is none)."""
    import numpy as np
    from matplotlib.ticker import MaxNLocator

    class Whole(MaxNLocator):
        def tick_values(self, vmin, vmax):
            ticks = np.asarray(super().tick_values(vmin, vmax))
            whole = np.round(ticks[np.abs(ticks - np.round(ticks)) < 1e-6])
            return whole if whole.size else np.array([np.round((vmin + vmax) / 2)])

    return Whole(integer=True, min_n_ticks=1)


def plot(rows: list[dict], path: Path) -> None:
    """Best fitness and number of species against budget (errorbars: std over seeds), in two
    panels that share the budget axis (on twin axes one line could hide the other), drawn on a
    `matplotlib.figure.Figure` (no pyplot, no backend change) and written as a PNG. The species
    panel has integer ticks (it counts species), and so has the budget axis when every budget
    is a whole number: also where the axis spans less than two integers (one budget, equal
    species counts), where matplotlib's default would tick fractions."""
    from matplotlib.figure import Figure

    rows = [
        r
        for r in rows
        if r["budget"] is not None
        and r["best_fitness"] is not None
        and r["num_species"] is not None
    ]
    x = [r["budget"] for r in rows]
    fig = Figure(figsize=(6, 5))
    fit_ax, species_ax = fig.subplots(2, 1, sharex=True)
    for ax, key, marker, color, label in (
        (fit_ax, "best_fitness", "o", "tab:blue", "best fitness"),
        (species_ax, "num_species", "s", "tab:orange", "species in the best team"),
    ):
        ys, errs = [r[key] for r in rows], [r[key + "_std"] for r in rows]
        ax.errorbar(x, ys, errs, marker=marker, color=color, capsize=3)
        ax.set_ylabel(label)
    species_ax.yaxis.set_major_locator(_whole_ticks())
    if all(float(b).is_integer() for b in x):
        species_ax.xaxis.set_major_locator(_whole_ticks())
    species_ax.set_xlabel("budget ($)")
    fig.tight_layout()
    fig.savefig(path, dpi=120, format="png")


def write_outputs(rows: list[dict], out_dir: Path, keys: tuple[str, ...] = ()) -> list[Path]:
    """table.md, table.csv and (for a sweep of budgets alone, no grid `keys`) budget.png."""
    out_dir = Path(out_dir)
    paths = [out_dir / TABLE_MD, out_dir / TABLE_CSV, out_dir / BUDGET_PLOT]
    # each replaced whole (`atomic_write_bytes`): a link planted in --out is never written through
    atomic_write_bytes(paths[0], markdown(rows, keys).encode())
    atomic_write_bytes(paths[1], csv_text(rows, keys).encode())
    if keys:
        return paths[:2]
    buf = io.BytesIO()
    plot(rows, buf)
    atomic_write_bytes(paths[2], buf.getvalue())
    return paths
