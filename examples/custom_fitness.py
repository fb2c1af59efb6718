"""Evolve with your own fitness function through the Python API: here a team scores only the
packages it delivers (no shaping terms for pick-ups, energy or closeness), still penalised over
the budget. Compare its best team with the built-in fitness's.

    python examples/custom_fitness.py                       # 10 generations, under a minute on a CPU
    python examples/custom_fitness.py --generations 50 --logdir runs
    python examples/custom_fitness.py --weights             # the same idea by the built-in weights

`--weights` needs no function: the raw-fitness weights of the paper's Table IV are run settings
(`w_delivery`, `w_collab_bonus`, `w_pickup`, `w_energy`, `w_proximity`, `w_closeness`,
`inactive_factor`, `fitness_floor`), keywords of `sc.evolve` and `--set KEY=VALUE` on the
command line; it sets every shaping weight to 0, so the built-in fitness counts deliveries only.

A fitness function takes (metrics, cost, cfg): `metrics` maps each per-episode measurement
("delivered_individual", "delivered_collab", "grips_delivered", "picked_individual",
"picked_collab", "mean_final_energy", "energy_used", "proximity", "closeness") to an [E]
tensor, one value per team-episode; `cost` is the [E] team cost in $; `cfg` is the run's
EvalConfig (budget, lam, objective, weights). It returns [E] scores; SwarmCoDe's marginal gate,
the mean over trials and the smoothing apply to them as to the built-in fitness. A run records
the function's name (summary.json: "fitness": "custom: ..."); resume it with the same function:
`sc.resume(run_dir, fitness=deliveries_only)`.
"""

from __future__ import annotations

import argparse

import torch

import swarmcode_torch as sc
from swarmcode_torch.coevo.fitness import budget_penalty


def deliveries_only(metrics: dict[str, torch.Tensor], cost: torch.Tensor, cfg) -> torch.Tensor:
    """One point per delivered package (a collaborative one too), a little for a pick-up so that
    a first generation that delivers nothing has a gradient, times the budget penalty."""
    delivered = metrics["delivered_individual"] + metrics["delivered_collab"]
    picked = metrics["picked_individual"] + metrics["picked_collab"]
    return (delivered + 0.1 * picked + 0.01) * budget_penalty(cost, cfg.budget, cfg.lam)


def main(argv: list[str] | None = None) -> sc.RunResult:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="two-niche")
    ap.add_argument("--generations", type=int, default=10)
    ap.add_argument("--population", type=int, default=20)
    ap.add_argument("--swarm-size", type=int, default=10)
    ap.add_argument("--ticks", type=int, default=150)
    ap.add_argument("--trials", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--logdir", default=None, help="write a run directory here (default: none, in memory)"
    )
    ap.add_argument(
        "--weights",
        action="store_true",
        help="no function: the built-in fitness with its shaping weights set to 0",
    )
    args = ap.parse_args(argv)

    how = (
        dict(w_pickup=0.0, w_energy=0.0, w_proximity=0.0, w_closeness=0.0)
        if args.weights
        else dict(fitness=deliveries_only)
    )
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
        **how,
        callback=lambda r: print(
            f"gen {r.generation}: best score "
            f"{r.best_fitness:.2f}, deliveries "
            f"{r.team['deliveries']:.1f}"
        ),
    )
    best = result.best_team
    print(
        f"fitness function: {result.config.fitness_function or 'built-in'}, weights "
        f"w_delivery={result.config.w_delivery:g} w_pickup={result.config.w_pickup:g} "
        f"w_closeness={result.config.w_closeness:g}"
    )
    print(
        f"best team: score {best['fitness']:.2f}, {best['deliveries']:.1f} deliveries, "
        f"cost ${best['cost']:.0f}, {best['species']} species"
    )
    if result.run_dir is not None:
        print(
            f"run directory: {result.run_dir}"
            + ("" if args.weights else " (resume: sc.resume(run_dir, fitness=deliveries_only))")
        )
    return result


if __name__ == "__main__":
    main()
