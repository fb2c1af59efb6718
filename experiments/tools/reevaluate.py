"""Re-evaluate the best team of committed runs on fresh seeds (`swarmcode_torch.evaluate`).

    python experiments/tools/reevaluate.py --episodes 20 --json OUT.json RUN_DIR [RUN_DIR ...]

For each run: the recorded fitness of its best team (the single-trial maximum a run keeps) and
the mean, sd and 95 % t interval of the same team's fitness on `--episodes` fresh seeds (from
1,000,000, disjoint from the seeds a run uses), its cost, species and deliveries. Prints one
Markdown row per run; `--json` writes every figure. Reads the run directories, writes nothing
else. A compact run (config.toml, summary.json) is enough.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import swarmcode_torch as sc


def row(run: str, episodes: int) -> dict:
    team = sc.evaluate(run, episodes=episodes).to_dict()["teams"][0]
    f = team["fitness"]
    return {
        "run": run,
        "generation": team["generation"],
        "recorded_fitness": team["recorded_fitness"],
        "fitness_mean": f["mean"],
        "fitness_sd": f["sd"],
        "fitness_low": f["low"],
        "fitness_high": f["high"],
        "episodes": f["n"],
        "cost": team["cost"],
        "species": team["species"],
        "deliveries_mean": team["deliveries_total"]["mean"],
    }


def _num(x: float) -> str:
    return f"{x:,.1f}" if abs(x) >= 10 else f"{x:.3f}"


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+")
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--json", type=Path)
    a = p.parse_args(argv)
    rows = []
    print("| run | generation | recorded (one trial) | re-evaluated mean | 95 % interval | sd |")
    print("|---|---|---|---|---|---|")
    for run in a.runs:
        r = row(run, a.episodes)
        rows.append(r)
        print(
            f"| {Path(run).name} | {r['generation']} | {_num(r['recorded_fitness'])} | "
            f"{_num(r['fitness_mean'])} | [{_num(r['fitness_low'])}, {_num(r['fitness_high'])}] | "
            f"{_num(r['fitness_sd'])} |",
            flush=True,
        )
    if a.json:
        a.json.write_text(json.dumps({"episodes": a.episodes, "runs": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
