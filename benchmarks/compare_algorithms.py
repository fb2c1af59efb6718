"""SwarmCoDe against its baselines on one scenario, with the same seeds and team-episode budget.

Algorithms (see swarmcode_torch/baselines.py):
  swarmcode               SwarmCoDe (dynamic speciation, dominance-sampled composition)
  homogeneous-ga          a plain GA over one design that every robot of the team copies
  ccea                    cooperative co-evolution with --ccea-species species fixed in advance
  swarmcode-no-dominance  SwarmCoDe with uniform team composition (dominance genes ignored)

SwarmCoDe runs 2 * P * trials team-episodes per generation (focal + baseline teams), the GA and
the CCEA P * trials, so they get twice the generations for the same budget. Every run's best team
is also re-scored on --eval-trials held-out environments, the same for every algorithm and seed.

Writes benchmarks/results/compare_<scenario>[_<tag>].json and .md. Examples:
    OMP_NUM_THREADS=2 python benchmarks/compare_algorithms.py            # small CPU defaults
    python benchmarks/compare_algorithms.py --device cuda --population 100 --swarm-size 20 \\
        --trials 3 --ticks 250 --generations 200 --seeds 0,1,2,3,4 --tag gpu
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import RESULTS_DIR, int_list, run_metadata, write_json  # noqa: E402

from swarmcode_torch.baselines import (
    ALGORITHMS,
    HELD_OUT_SEED,
    compare,
    plan_generations,
    summarize,
)
from swarmcode_torch.sim.runtime import resolve_device  # noqa: E402

LABELS = {
    "swarmcode": "SwarmCoDe",
    "homogeneous-ga": "Homogeneous GA (1 design)",
    "ccea": "CCEA, {k} fixed species",
    "swarmcode-no-dominance": "SwarmCoDe, no dominance (uniform)",
}


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenario", default="four-niche", help="built-in scenario name or TOML path")
    p.add_argument("--seeds", type=int_list, default=[0, 1, 2], help="comma-separated seeds")
    p.add_argument(
        "--generations",
        type=int,
        default=10,
        help="SwarmCoDe generations; the others get the same number of team-episodes",
    )
    p.add_argument(
        "--episodes",
        type=int,
        default=None,
        help="team-episode budget instead of --generations (a multiple of 2 P trials)",
    )
    p.add_argument("--population", type=int, default=16)
    p.add_argument("--swarm-size", type=int, default=10)
    p.add_argument("--trials", type=int, default=1)
    p.add_argument("--ticks", type=int, default=100)
    p.add_argument("--budget", type=float, default=None, help="fabrication budget in $")
    p.add_argument("--objective", choices=("fitness", "roi"), default="fitness")
    p.add_argument("--ccea-species", type=int, default=4, help="species of the fixed CCEA")
    p.add_argument(
        "--eval-trials",
        type=int,
        default=16,
        help="held-out environments on which every best team is re-scored",
    )
    p.add_argument(
        "--algorithms",
        default=",".join(ALGORITHMS),
        help="comma-separated subset of " + ", ".join(ALGORITHMS),
    )
    p.add_argument("--device", default="auto", help="auto, cpu or cuda")
    p.add_argument("--tag", default="", help="suffix of the output file names")
    p.add_argument("--out", type=Path, default=RESULTS_DIR, help="output folder")
    return p.parse_args(argv)


def label(name: str, k: int) -> str:
    return LABELS.get(name, name).format(k=k)


def markdown(meta: dict, setup: dict, table: list[dict]) -> str:
    k = setup["ccea_species"]
    lines = [
        f"# SwarmCoDe vs baselines: `{setup['scenario']}`",
        "",
        f"{len(setup['seeds'])} seeds ({', '.join(map(str, setup['seeds']))}); population "
        f"{setup['population']}, swarm size {setup['swarm_size']}, trials {setup['trials']}, "
        f"ticks {setup['ticks']}, budget {setup['budget']}, objective {setup['objective']}; "
        f"{setup['episodes']} team-episodes per run for every algorithm. "
        f"Device: {meta['device']} ({meta['device_name']}), torch {meta['torch']}, "
        f"commit {meta['git_commit']}{' (dirty)' if meta.get('git_dirty') else ''}.",
        "",
        "| Algorithm | Generations | Team-episodes | Best fitness (in run) | Held-out fitness "
        "| Held-out deliveries | Species in best team | Team cost ($) | Seconds per run |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in table:

        def pm(col: str, fmt: str = ".1f") -> str:
            return f"{r[col]:{fmt}} ± {r[col + '_std']:{fmt}}"  # noqa: B023 - called in this loop

        lines.append(
            f"| {label(r['algorithm'], k)} | {r['generations']} | {r['episodes']} "
            f"| {pm('best_fitness')} | {pm('heldout_fitness')} | {pm('heldout_deliveries', '.2f')} "
            f"| {pm('species', '.2g')} | {pm('team_cost', '.0f')} | {r['seconds']:.1f} |"
        )
    lines += [
        "",
        "Mean ± sample standard deviation over seeds. *Best fitness (in run)*: the highest team "
        f"score seen during the run (mean over its {setup['trials']} trial(s); a maximum over "
        "noisy evaluations, so biased upwards); for SwarmCoDe, over each generation's best team, "
        "the team of its fittest (gated) individual. *Held-out*: that same best team re-scored on "
        f"{setup['eval_trials']} fixed environments (seed {HELD_OUT_SEED}), identical for every "
        "algorithm and seed, not counted in the budget. *Species in best team*: distinct designs "
        "in it.",
        "",
        f"Command: `{meta['command']}`",
        "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    a = parse_args(argv)
    algorithms = [s.strip() for s in a.algorithms.split(",") if s.strip()]
    device = resolve_device(a.device)
    episodes = a.episodes if a.episodes is not None else a.generations * 2 * a.population * a.trials
    plan = plan_generations(episodes, a.population, a.trials)
    meta = run_metadata(device)
    setup = {
        "scenario": a.scenario,
        "seeds": a.seeds,
        "episodes": episodes,
        "generations": {k: plan[k] for k in algorithms},
        "population": a.population,
        "swarm_size": a.swarm_size,
        "trials": a.trials,
        "ticks": a.ticks,
        "budget": a.budget,
        "objective": a.objective,
        "ccea_species": a.ccea_species,
        "eval_trials": a.eval_trials,
        "held_out_seed": HELD_OUT_SEED,
        "algorithms": algorithms,
    }
    print(
        f"{len(algorithms)} algorithms x {len(a.seeds)} seeds, {episodes} team-episodes each, "
        f"on {meta['device']} ({meta['device_name']})",
        file=sys.stderr,
    )

    def progress(row: dict) -> None:
        print(
            f"  {row['algorithm']:<24} seed {row['seed']}: best {row['best_fitness']:8.1f}  "
            f"held-out {row['heldout_fitness']:8.1f}  species {row['species']:2d}  "
            f"{row['episodes']} episodes  {row['seconds']:.1f} s",
            file=sys.stderr,
        )

    t0 = time.perf_counter()
    rows = compare(
        scenario=a.scenario,
        seeds=a.seeds,
        episodes_budget=episodes,
        population=a.population,
        swarm_size=a.swarm_size,
        trials=a.trials,
        ticks=a.ticks,
        budget=a.budget,
        objective=a.objective,
        device=str(device),
        num_species=a.ccea_species,
        eval_trials=a.eval_trials,
        algorithms=algorithms,
        progress=progress,
    )
    table = summarize(rows)
    meta["total_seconds"] = time.perf_counter() - t0

    stem = f"compare_{Path(a.scenario).stem}" + (f"_{a.tag}" if a.tag else "")
    out = write_json(
        {"meta": meta, "setup": setup, "table": table, "runs": rows}, a.out / f"{stem}.json"
    )
    md = markdown(meta, setup, table)
    (a.out / f"{stem}.md").write_text(md)
    print(md)
    print(f"wrote {out} and {out.with_suffix('.md')}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
