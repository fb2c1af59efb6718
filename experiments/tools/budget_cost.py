"""Team cost against the budget, window by window, for budget runs.

    python experiments/tools/budget_cost.py RUN_DIR [RUN_DIR ...] [--window 50] [--json OUT]

For each run (its teams.jsonl: the best team of every generation) and each window of
`--window` generations: the median team cost, the share of generations whose team is over the
budget, the median score and collaborative deliveries, and, for the teams over and within the
budget separately, the median score and the median score before the budget penalty (score /
P_budget, with P_budget = max(0.05, exp(-lam (cost - budget))) as in the fitness; lam from the
run's config.toml). Then one row per run, the paper's Table III columns: the run's best team
(summary.json: fitness, cost, deliveries, species) and the medians of its last `--window`
generations (`app.analysis.run_dynamics`: species in the best team and the population, niches,
best-team score). Used in docs/RESULTS.md ("The budget sweep's two ends with the 0.4
defaults", "The budget sweep and ROI with the 0.5 defaults").
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path

import torch

from swarmcode_torch.app.analysis import run_dynamics
from swarmcode_torch.app.runs import RunError, read_config, read_summary, read_teams
from swarmcode_torch.coevo.dynamics import mean_std
from swarmcode_torch.coevo.fitness import budget_penalty


def penalty(cost: float, budget: float, lam: float) -> float:
    """P_budget of one team, as the fitness computes it (`fitness.budget_penalty`)."""
    return float(budget_penalty(torch.tensor(cost), budget, lam))


def median(values: list[float]) -> float | None:
    return round(statistics.median(values), 1) if values else None


def windows(run: Path, width: int) -> dict:
    cfg = read_config(run)
    budget, lam = cfg.budget, cfg.lam
    if budget is None:
        raise SystemExit(f"error: {run} has no budget")
    rows = list(read_teams(run).values())
    if not rows:
        raise RunError(f"{run} has no best-team records (teams.jsonl)")
    out = []
    end = max(r["generation"] for r in rows) + 1
    for lo in range(0, end, width):
        w = [r for r in rows if lo <= r["generation"] < lo + width]
        over = [r for r in w if r["cost"] > budget]
        within = [r for r in w if r["cost"] <= budget]

        def part(rs: list[dict]) -> dict:
            return {
                "n": len(rs),
                "score": median([r["fitness"] for r in rs]),
                "score_before_penalty": median(
                    [r["fitness"] / penalty(r["cost"], budget, lam) for r in rs]
                ),
                "cost": median([r["cost"] for r in rs]),
                "collab": median([r["deliveries_collab"] for r in rs]),
            }

        out.append(
            {
                "generations": [lo, lo + len(w) - 1],
                "cost": median([r["cost"] for r in w]),
                "over_share": round(len(over) / len(w), 2),
                "score": median([r["fitness"] for r in w]),
                "collab": median([r["deliveries_collab"] for r in w]),
                "over": part(over),
                "within": part(within),
            }
        )
    summary = read_summary(run)
    tail = run_dynamics(run, [(end - width, end)])[0]
    best = {
        k: summary[k]
        for k in (
            "best_fitness",
            "team_cost",
            "deliveries",
            "deliveries_individual",
            "deliveries_collab",
            "num_species",
            "niches",
        )
    }
    last = {k: tail[k] for k in ("team_species", "population_species", "niches", "team_score")}
    return {
        "run": str(run),
        "budget": budget,
        "seed": cfg.seed,
        "lam": lam,
        "windows": out,
        "best": best,
        "last": last,
        "last_cost": out[-1]["cost"],
        "last_over_share": out[-1]["over_share"],
    }


def mean_std_text(values: list[float]) -> str:
    """ "mean ± std" over seeds (`dynamics.mean_std`; a single value alone)."""
    mean, std = mean_std(values)
    return f"{mean:,.0f}" if len(values) == 1 else f"{mean:,.0f} ± {std:,.0f}"


def by_budget(result: list[dict]) -> list[str]:
    """Markdown rows of the sweep over seeds: per budget, the seeds' runs side by side."""
    rows = [
        "| budget | seeds | best fitness | last: score | last: team species (per seed) | "
        "last: niches | last: population species | last: team cost | last: over budget |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for budget in sorted({r["budget"] for r in result}):
        rs = sorted((r for r in result if r["budget"] == budget), key=lambda r: r["seed"])
        each = lambda f, fmt="g": ", ".join(format(f(r), fmt) for r in rs)  # noqa: E731, B023
        rows.append(
            f"| {budget:,.0f} | {', '.join(str(r['seed']) for r in rs)} "
            f"| {mean_std_text([r['best']['best_fitness'] for r in rs])} "
            f"| {mean_std_text([r['last']['team_score'] for r in rs])} "
            f"| {each(lambda r: r['last']['team_species'])} "
            f"| {each(lambda r: r['last']['niches'])} "
            f"| {each(lambda r: r['last']['population_species'])} "
            f"| {each(lambda r: r['last_cost'], ',.0f')} "
            f"| {each(lambda r: r['last_over_share'], '.0%')} |"
        )
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--window", type=int, default=50)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args(argv)
    try:
        result = [windows(r, a.window) for r in a.runs]
    except RunError as e:
        raise SystemExit(f"error: {e}") from None
    for res in result:
        print(f"{res['run']} (budget {res['budget']:.0f}, lam {res['lam']})")
        print(
            "| generations | median cost | over budget | score | collab | over: n, score, "
            "before penalty | within: n, score, before penalty |"
        )
        print("|---|---|---|---|---|---|---|")
        for w in res["windows"]:
            o, i = w["over"], w["within"]
            print(
                f"| {w['generations'][0]}–{w['generations'][1]} | {w['cost']} | "
                f"{w['over_share']:.0%} | {w['score']} | {w['collab']} | {o['n']}, {o['score']}, "
                f"{o['score_before_penalty']} | {i['n']}, {i['score']}, "
                f"{i['score_before_penalty']} |"
            )
    print(
        "| budget | best fitness | team cost | deliveries (individual + collaborative) | "
        "species | last: team species / population species / niches | last: score |"
    )
    print("|---|---|---|---|---|---|---|")
    for res in sorted(result, key=lambda r: r["budget"]):
        b, t = res["best"], res["last"]
        print(
            f"| {res['budget']:,.0f} | {b['best_fitness']:,.0f} | {b['team_cost']:,.0f} | "
            f"{b['deliveries']:.1f} ({b['deliveries_individual']:.1f} + "
            f"{b['deliveries_collab']:.1f}) | {b['num_species']} | {t['team_species']:g} / "
            f"{t['population_species']:g} / {t['niches']:g} | {t['team_score']:,.0f} |"
        )
    if len({r["budget"] for r in result}) < len(result):  # several seeds of a budget
        print(
            "\n".join(["", "Over seeds (last: the last --window generations):"] + by_budget(result))
        )
    if a.json:
        a.json.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
