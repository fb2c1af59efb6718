"""Turn the raw run directories of the paper experiments into the compact files and figures that
docs/RESULTS.md shows.

    python experiments/2026-11-23-paper-rounds-pre-v02/make_results.py RAW_ROOT [--only niche] [--out DIR]

RAW_ROOT holds `niche/`, `budget/` (a `swarmcode-torch sweep --out` directory), `roi/` and
`swarm200/`, each with run directories as `evolve` writes them (summary.json, teams.jsonl,
config.toml, checkpoint.pt); with `--only niche`, only `niche/`. For each run this writes,
under <DIR, default experiments/2026-11-23-paper-rounds-pre-v02/first-round-h100>/<experiment>/<run>/:
config.toml, summary.json, history.json (species composition per generation) and
generations.csv (the best team of every generation); plus figures and the budget sweep's
table.md / table.csv / budget.png, and prints the tables that RESULTS.md quotes.
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from swarmcode_torch.app.runs import load_checkpoint  # noqa: E402

from swarmcode_torch.app.reporting import composition_figure  # noqa: E402
from swarmcode_torch.app.sweep import table_rows, write_outputs  # noqa: E402

HERE = Path(__file__).resolve().parent
FIELDS = ["generation", "fitness", "cost", "species", "deliveries", "deliveries_individual",
          "deliveries_collab", "energy_used", "species_in_population"]


def run_label(run_dir: Path) -> str:
    """'four-niche__1__20261122-195904' -> 'four-niche-seed1' (and since 0.3.1
    'budget__b4000__1__...' -> 'budget-b4000-seed1'); sweep names are kept."""
    parts = run_dir.name.split("__")
    return "-".join(parts[:-2]) + f"-seed{parts[-2]}" if len(parts) >= 3 else run_dir.name


def compact(run_dir: Path, out_dir: Path, figure: bool = True) -> dict:
    """Copy one run's small files, write history.json and generations.csv; the run's record."""
    out_dir.mkdir(parents=True, exist_ok=True)
    for name in ("config.toml", "summary.json"):
        shutil.copy(run_dir / name, out_dir / name)
    history = load_checkpoint(run_dir)["history"]
    (out_dir / "history.json").write_text(json.dumps(history))
    pop_species = {h["generation"]: len(h["population"]) for h in history}
    by_gen = {}                     # a resumed run may repeat generations: the last record wins
    for line in (run_dir / "teams.jsonl").read_text().splitlines():
        if line:
            t = json.loads(line)
            by_gen[t["generation"]] = t
    teams = [by_gen[g] for g in sorted(by_gen)]
    with open(out_dir / "generations.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        for t in teams:
            w.writerow({**{k: t[k] for k in FIELDS[:-1]},
                        "species_in_population": pop_species.get(t["generation"], "")})
    if figure:
        fig = composition_figure(history)
        fig.savefig(out_dir / "composition.png", dpi=60)
        plt.close(fig)
    summary = json.loads((run_dir / "summary.json").read_text())
    return {"label": run_label(run_dir), "dir": out_dir, "summary": summary, "teams": teams,
            "history": history}


def last_window(values: list, n: int = 50) -> list:
    return values[-n:] if len(values) >= n else values


def median(values: list) -> float:
    v = sorted(values)
    return v[len(v) // 2] if v else float("nan")


SCENARIOS = ["one-niche", "two-niche", "four-niche"]
PAPER_SPECIES = {"one-niche": 1, "two-niche": 2, "four-niche": 4}


def runs_of(records: list[dict], scenario: str) -> list[dict]:
    """The records of one scenario, by seed."""
    return sorted((r for r in records if r["label"].startswith(scenario + "-")),
                  key=lambda r: r["label"])


def scenario_panels(records: list[dict], path: Path, ylabel: str, series, height: float,
                    **plot_kw) -> None:
    """One panel per scenario, one line per run: series(record) -> (x, y)."""
    fig, axes = plt.subplots(1, 3, figsize=(14, height), sharey=plot_kw.pop("sharey", False))
    for ax, sc in zip(axes, SCENARIOS):
        for r in runs_of(records, sc):
            ax.plot(*series(r), label=r["label"].split("-")[-1], **plot_kw)
        ax.set_title(sc)
        ax.set_xlabel("generation")
        ax.set_ylabel(ylabel)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def niche_report(records: list[dict], out: Path) -> None:
    print("\n| scenario | seed | generations | best-team species (best of run) | best-team species, median of the last 50 generations | last 50 with the paper's count | population species, median of the last 50 | best fitness | deliveries |")
    print("|---|---|---|---|---|---|---|---|---|")
    for sc in SCENARIOS:
        for r in runs_of(records, sc):
            s, teams = r["summary"], r["teams"]
            window = [t["species"] for t in last_window(teams)]
            hit = sum(n == PAPER_SPECIES[sc] for n in window) / max(1, len(window))
            pop_sp = median([len(h["population"]) for h in last_window(r["history"])])
            print(f"| {sc} | {r['label'].split('seed')[-1]} | {s['generation'] + 1} | {s['num_species']} | "
                  f"{median(window)} | {hit:.0%} | {pop_sp} | {s['best_fitness']:.0f} | {s['deliveries']:.1f} |")
    scenario_panels(records, out / "fitness.png", "fitness of the generation's best team",
                    lambda r: ([t["generation"] for t in r["teams"]],
                               [t["fitness"] for t in r["teams"]]), 3.4, lw=0.7)


def species_lines(records: list[dict], out: Path) -> None:
    """Species in the best team per generation (20-generation running median), per run."""
    def series(r):
        sp = [t["species"] for t in r["teams"]]
        return ([t["generation"] for t in r["teams"]],
                [median(sp[max(0, i - 19):i + 1]) for i in range(len(sp))])

    scenario_panels(records, out / "team_species.png",
                    "species in the best team (20-gen. median)", series, 3.2, sharey=True)


def designs_table(summary: dict) -> None:
    print("\n| robots | species | tool | radius | chassis | battery | motor | torque pt | battery pt | $ each |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for d in summary["designs"]:
        print(f"| {d['count']} | {d['species']} | {d['effector']} | {d['radius']:.2f} | {d['chassis_tier']} | "
              f"{d['battery_tier']} | {d['motor_tier']} | {d['torque_point']:.2f} | {d['battery_point']:.2f} | {d['cost']:.0f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("raw", type=Path, help="directory holding niche/ (budget/, roi/, swarm200/)")
    ap.add_argument("--only", choices=["all", "niche"], default="all")
    ap.add_argument("--out", type=Path, default=HERE / "first-round-h100", help="where the compact files go")
    args = ap.parse_args()
    raw, out = args.raw, args.out
    niche = [compact(d, out / "niche" / run_label(d), figure=run_label(d).endswith("seed0"))
             for d in sorted((raw / "niche").iterdir())]
    niche_report(niche, out / "niche")
    species_lines(niche, out / "niche")
    for r in niche:
        print(f"\n{r['label']} best team (generation {r['summary']['best_generation']}):")
        designs_table(r["summary"])
    if args.only == "niche":
        return

    sweep_out = out / "budget_sweep"
    runs = []
    for d in sorted((raw / "budget").iterdir()):
        if d.is_dir():
            rec = compact(d, sweep_out / d.name)
            runs.append((rec["summary"]["budget"], 0, sweep_out / d.name))
            print(f"\n{d.name}: generation {rec['summary']['generation'] + 1}, best team:")
            designs_table(rec["summary"])
    write_outputs(table_rows(runs), sweep_out)
    print("\n" + (sweep_out / "table.md").read_text())

    for name in ("roi", "swarm200"):
        for d in sorted((raw / name).iterdir()):
            rec = compact(d, out / name)
            s = rec["summary"]
            print(f"\n{name}: generation {s['generation'] + 1}, best fitness {s['best_fitness']:.4g} "
                  f"(generation {s['best_generation']}), cost {s['team_cost']:.0f}, "
                  f"{s['num_species']} species, deliveries {s['deliveries_individual']:.1f} + "
                  f"{s['deliveries_collab']:.1f}")
            designs_table(s)
            first = [t for t in rec["teams"] if t["generation"] < 50]
            multi = [t["generation"] for t in first
                     if len({d["effector"] for d in t["designs"]}) > 1]
            print(f"first generation whose best team mixes suction and pincher robots: "
                  f"{multi[0] if multi else 'none'}")


if __name__ == "__main__":
    main()
