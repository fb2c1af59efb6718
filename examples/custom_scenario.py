"""Evolve a swarm for a custom scenario (three-niche.toml beside this file) through the Python
API, then print the best team and the last generations' metrics.

    python examples/custom_scenario.py                     # 10 generations, about a minute on a CPU
    python examples/custom_scenario.py --generations 50 --logdir runs
    python examples/custom_scenario.py --scenario examples/three-niche-carbon.toml

three-niche-carbon.toml is the same world with a hardware catalog of its own
(carbon-hardware.toml beside it: `hardware = "carbon-hardware.toml"`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import swarmcode_torch as sc

SCENARIO = Path(__file__).with_name("three-niche.toml")


def main(argv: list[str] | None = None) -> sc.RunResult:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(SCENARIO), help="a scenario TOML file")
    ap.add_argument("--generations", type=int, default=10)
    ap.add_argument("--population", type=int, default=20)
    ap.add_argument("--swarm-size", type=int, default=10)
    ap.add_argument("--ticks", type=int, default=150)
    ap.add_argument("--trials", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--logdir", default=None, help="write a run directory here (default: none, in memory)"
    )
    args = ap.parse_args(argv)

    scenario = sc.load_scenario(args.scenario)  # a Scenario object: check it, change it, ...
    print(f"{scenario.name}: {scenario.description}")
    print(f"chassis strength per tier (kg/m^2): {scenario.hardware.chassis_strength}")
    result = sc.evolve(
        scenario=args.scenario,
        generations=args.generations,
        population=args.population,
        swarm_size=args.swarm_size,
        ticks=args.ticks,
        trials=args.trials,
        seed=args.seed,
        device="cpu",
        logdir=args.logdir,
        callback=lambda r: print(
            f"gen {r.generation}: best fitness {r.best_fitness:.1f}, species {r.num_species}"
        ),
    )
    best = result.best_team
    print(
        f"best team: fitness {best['fitness']:.1f}, cost ${best['cost']:.0f}, "
        f"{best['species']} species, {best['niches']} niches"
    )
    for d in best["designs"]:
        print(
            f"  {d['count']} x species {d['species']}: {d['effector']}, radius "
            f"{d['radius']:.2f} m, lifts package classes {d['capability']}"
        )
    if result.run_dir is not None:
        print(f"run directory: {result.run_dir}")
    return result


if __name__ == "__main__":
    main()
