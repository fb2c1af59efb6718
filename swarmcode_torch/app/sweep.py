"""Budget sweeps: one evolution per (budget, seed), summarised as the paper's Table III."""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

COLUMNS = ("budget", "best_fitness", "team_cost", "deliveries", "deliveries_individual",
           "deliveries_collab", "energy_used", "num_species")
HEADERS = ("Budget", "Best fitness", "Team cost", "Total deliveries", "Individual",
           "Collaborative", "Avg. energy used", "# species")


def run_name(budget: float | None, seed: int) -> str:
    b = "none" if budget is None else f"{budget:g}"
    return f"budget-{b}_seed-{seed}"


def read_summary(run_dir: Path) -> dict:
    path = Path(run_dir) / "summary.json"
    if not path.is_file():
        raise ValueError(f"{run_dir} has no summary.json")
    return json.loads(path.read_text())


def table_rows(runs: list[tuple[float | None, int, Path]]) -> list[dict]:
    """One row per budget: each column's mean over seeds (and its std as `<col>_std`)."""
    by_budget: dict = {}
    for budget, seed, run_dir in runs:
        by_budget.setdefault(budget, []).append(read_summary(run_dir))
    rows = []
    for budget, summaries in by_budget.items():
        row = {"budget": budget, "seeds": len(summaries)}
        for col in COLUMNS[1:]:
            vals = [float(s[col]) for s in summaries]
            mean = sum(vals) / len(vals)
            row[col] = mean
            row[f"{col}_std"] = math.sqrt(sum((v - mean) ** 2 for v in vals) / len(vals))
        rows.append(row)
    rows.sort(key=lambda r: math.inf if r["budget"] is None else r["budget"])
    return rows


def _fmt(v, col: str) -> str:
    if v is None:
        return "none"
    if col in ("budget", "team_cost"):
        return f"{v:.0f}"
    return f"{v:.1f}" if col != "num_species" else f"{v:.2g}"


def markdown(rows: list[dict]) -> str:
    seeds = max((r["seeds"] for r in rows), default=1)
    lines = ["| " + " | ".join(HEADERS) + " |", "|" + "---|" * len(HEADERS)]
    for r in rows:
        cells = []
        for col in COLUMNS:
            cell = _fmt(r[col], col)
            if seeds > 1 and col != "budget":
                cell += f" ± {_fmt(r[col + '_std'], col)}"
            cells.append(cell)
        lines.append("| " + " | ".join(cells) + " |")
    note = f"\nMean over {seeds} seeds (± std); the best team of each run." if seeds > 1 else \
        "\nThe best team of each run."
    return "\n".join(lines) + "\n" + note + "\n"


def csv_text(rows: list[dict]) -> str:
    buf = io.StringIO()
    fields = ["budget", "seeds"] + [c for col in COLUMNS[1:] for c in (col, f"{col}_std")]
    w = csv.DictWriter(buf, fieldnames=fields)
    w.writeheader()
    for r in rows:
        w.writerow({k: ("none" if r[k] is None else r[k]) for k in fields})
    return buf.getvalue()


def plot(rows: list[dict], path: Path) -> None:
    """Best fitness and number of species against budget (errorbars: std over seeds), drawn on a
    `matplotlib.figure.Figure` (no pyplot, no backend change) and written as a PNG."""
    from matplotlib.figure import Figure

    rows = [r for r in rows if r["budget"] is not None]
    x = [r["budget"] for r in rows]
    fig = Figure(figsize=(6, 3.6))
    ax1 = fig.subplots()
    ax1.errorbar(x, [r["best_fitness"] for r in rows], [r["best_fitness_std"] for r in rows],
                 marker="o", color="tab:blue", capsize=3)
    ax1.set_xlabel("budget ($)")
    ax1.set_ylabel("best fitness", color="tab:blue")
    ax2 = ax1.twinx()
    ax2.errorbar(x, [r["num_species"] for r in rows], [r["num_species_std"] for r in rows],
                 marker="s", color="tab:orange", capsize=3)
    ax2.set_ylabel("species in the best team", color="tab:orange")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def write_outputs(rows: list[dict], out_dir: Path) -> list[Path]:
    out_dir = Path(out_dir)
    paths = [out_dir / "table.md", out_dir / "table.csv", out_dir / "budget.png"]
    paths[0].write_text(markdown(rows))
    paths[1].write_text(csv_text(rows))
    plot(rows, paths[2])
    return paths
