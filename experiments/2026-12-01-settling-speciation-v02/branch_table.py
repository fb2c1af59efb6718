"""The table of a branch experiment: each branch beside its control (the run it was branched
from), medians over the generations after the branch.

    python experiments/2026-12-01-settling-speciation-v02/branch_table.py LABEL=CONTROL,BRANCH[@FROM] [...] [--to 300] [--json OUT]

For each pair, over generations FROM (default 100) to before --to: the medians that
`swarmcode-torch dynamics --window FROM:TO` prints (best-team and population species, niches,
founding, founding of species alive two generations or more, best-team score), and from
teams.jsonl the number of generations whose best team covers fewer niches than the most the
control's best team ever covered ("a niche short"), and the range of niches over the last 50
generations. Used in docs/RESULTS.md ("How a niche is lost").
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from swarmcode_torch.app.analysis import run_dynamics
from swarmcode_torch.app.runs import read_teams


def row(run: Path, start: int, end: int, full: int) -> dict:
    d = run_dynamics(run, [(start, end)])[0]
    teams = read_teams(run)
    niches = {g: int(r["niches"]) for g, r in teams.items() if start <= g < end}
    tail = [n for g, n in niches.items() if g >= end - 50]
    return {**d, "short": sum(n < full for n in niches.values()),
            "tail_niches": [min(tail), max(tail)] if tail else None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pairs", nargs="+", metavar="LABEL=CONTROL,BRANCH[@FROM]")
    ap.add_argument("--to", type=int, default=300)
    ap.add_argument("--json")
    args = ap.parse_args()
    out = []
    print("| run (window) | best-team species | population species | niches | generations a niche "
          "short | niches, last 50 | founded a generation | lasting | best-team score |")
    print("|---|---|---|---|---|---|---|---|---|")
    for pair in args.pairs:
        label, _, runs = pair.partition("=")
        runs, _, start = runs.partition("@")
        control, branch = (Path(p) for p in runs.split(","))
        start = int(start or 100)
        full = max(int(r["niches"]) for r in read_teams(control).values())
        for name, run in (("control", control), ("branch", branch)):
            if not (run / "checkpoint.pt").is_file():
                print(f"{label}: {run} has no checkpoint; left out", file=sys.stderr)
                continue
            r = row(run, start, args.to, full)
            out.append({"label": label, "run": name, "path": str(run), "from": start, **r})
            t = r["tail_niches"]
            print(f"| {label} {name} ({start}–{args.to - 1}) | {r['team_species']:g} | "
                  f"{r['population_species']:g} | {r['niches']:g} | {r['short']} | "
                  f"{t[0]}–{t[1]} | {r['founded_per_generation']:.2f} | "
                  f"{r['founded_lasting_per_generation']:.2f} | {r['team_score']:,.0f} |")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
