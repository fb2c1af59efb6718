"""One line per operator and scenario from the branch tables of experiments/2026-12-01-settling-speciation-v02/niche_loss
(written by `branch_table.py --json`): over the seeds that were branched, the mean best-team
species of the branches and of their controls, the generations a niche short summed over the
seeds, and the mean change of the best-team score against the control.

    python experiments/2026-12-01-settling-speciation-v02/branch_overview.py [TABLE.json ...]

Without arguments, the tables of the operators in docs/RESULTS.md ("How a niche is lost").
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent / "cpu" / "v02" / "niche_loss"
TABLES = {"effector_flip = prototype": "prototype_flip/table.json",
          "evaluated_partners = true": "evaluated_partners/table_300.json",
          "quota_basis = mean": "quota_mean_table.json",
          "gate_margin = 0.1": "gate_margin_table.json",
          "quota_inertia = 0.5": "quota_inertia_table.json",
          "quota_basis = sqrt": "quota_sqrt_table.json",
          "quota_size_exponent = 0.75": "quota_exponent_075_table.json",
          "partners_per_niche = one": "partners_one_table.json",
          "partners_per_niche = one, quota_size_exponent = 0.75": "partners_one_exp075_table.json",
          "none (null branch, --reseed 1)": "null_branch_table.json",
          "none (null branch, --reseed 2)": "null_branch_2_table.json"}


def overview(rows: list[dict]) -> list[dict]:
    out = []
    for scenario in sorted({r["label"].rsplit(" ", 1)[0] for r in rows}):
        pairs = {}
        for r in rows:
            if r["label"].rsplit(" ", 1)[0] == scenario:
                pairs.setdefault(r["label"], {})[r["run"]] = r
        pairs = [p for p in pairs.values() if "control" in p and "branch" in p]
        if not pairs:
            continue
        n = len(pairs)
        out.append({
            "scenario": scenario, "seeds": n,
            "team_species": sum(p["branch"]["team_species"] for p in pairs) / n,
            "control_team_species": sum(p["control"]["team_species"] for p in pairs) / n,
            "short": sum(p["branch"]["short"] for p in pairs),
            "control_short": sum(p["control"]["short"] for p in pairs),
            "score_change": sum(p["branch"]["team_score"] / p["control"]["team_score"] - 1
                                for p in pairs) / n})
    return out


def main() -> None:
    tables = {Path(a).stem: Path(a) for a in sys.argv[1:]} or \
        {k: HERE / v for k, v in TABLES.items()}
    print("| operator | scenario | seeds | best-team species: branch / control | generations "
          "a niche short: branch / control | best-team score vs control |")
    print("|---|---|---|---|---|---|")
    for name, path in tables.items():
        if not path.is_file():
            print(f"| {name} | (no table: {path.name}) | | | | |")
            continue
        for o in overview(json.loads(path.read_text())):
            print(f"| {name} | {o['scenario']} | {o['seeds']} | {o['team_species']:.1f} / "
                  f"{o['control_team_species']:.1f} | {o['short']} / {o['control_short']} | "
                  f"{o['score_change']:+.0%} |")


if __name__ == "__main__":
    main()
