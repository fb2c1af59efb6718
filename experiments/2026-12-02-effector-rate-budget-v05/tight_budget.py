"""What a second species is worth at a budget: a run's best teams against one-effector copies.

    python experiments/2026-12-02-effector-rate-budget-v05/tight_budget.py RUN_DIR [RUN_DIR ...] [--window 50] [--every 5]
        [--envs 32] [--seed 7] [--json OUT]

For every `--every`-th generation of the last `--window` of a budget run (teams.jsonl: the best
team of each generation), the team is scored as it is and as one *one-effector team* per
effector it holds: the team's designs of that effector alone, their counts scaled up to the
team's size (largest remainder). All variants run in the same `--envs` environments (one
batch, drawn from `--seed`), so the comparison is paired. For each variant: the raw fitness
F_raw (mean over the environments), the team cost (robot costs + the scenario's overhead per
species) and the score after the run's budget penalty.

Then, per run (medians over the sampled generations): R = F_raw(team) / F_raw(best
one-effector team), the penalty P_budget each pays at the run's budget, the break-even ratio
P(C_one) / P(C_team) (the one-effector team scores more when R is below it) and in how many
generations the team scores more after the penalty. This is the arithmetic of "a restrictive
budget necessitates a homogeneous generalist swarm" for the teams the run evolved. The
one-effector copies run trees evolved for a mixed team, so they bound the best one-effector
team from below.

    python experiments/2026-12-02-effector-rate-budget-v05/tight_budget.py --paper

applies the same arithmetic to the paper's own Table III: each row's team, from its deliveries
and energy, under the paper's F_raw (`fitness.raw_fitness`, the paper's weights) and penalty
(`fitness.budget_penalty`, lambda = 0.001), scored at every budget of the table. The terms the
table does not give are bounded: the lower bound counts deliveries only, and collaborative
packages with no grip points (their 50 bonus alone); the upper bound adds two grip points per
collaborative package, a pick-up per package of the world (20), proximity 10 (its maximum) and
closeness 1 (its maximum). Used in docs/RESULTS.md ("The tightest budget").
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import statistics
from pathlib import Path

import torch

from swarmcode_torch.app.render import team_genome
from swarmcode_torch.app.runs import RunError, read_config, read_teams, run_scenario
from swarmcode_torch.coevo.evaluation import simulate_teams
from swarmcode_torch.coevo.fitness import budget_penalty, raw_fitness, team_cost
from swarmcode_torch.coevo.population import Population
from swarmcode_torch.sim import bt
from swarmcode_torch.sim.layout import make_layouts
from swarmcode_torch.sim.state import WorldParams


def scaled_counts(counts: list[int], total: int) -> list[int]:
    """`counts` scaled to add up to `total` (largest remainder; ties to the earlier entry)."""
    s = sum(counts)
    if s <= 0:
        raise ValueError("no robot to scale")
    exact = [c * total / s for c in counts]
    out = [math.floor(x) for x in exact]
    order = sorted(range(len(counts)), key=lambda i: (-(exact[i] - out[i]), i))
    for i in order[:total - sum(out)]:
        out[i] += 1
    return out


def variants(designs: list[dict]) -> dict[str, list[dict]]:
    """"team": the designs as they are; for a team of both effectors, "suction" and "pincher":
    the designs of that effector alone, scaled to the team's size."""
    size = sum(int(d["count"]) for d in designs)
    out = {"team": designs}
    if len({d["effector"] for d in designs}) < 2:
        return out                                    # a one-effector team already
    for eff in ("suction", "pincher"):
        own = [d for d in designs if d["effector"] == eff]
        counts = scaled_counts([int(d["count"]) for d in own], size)
        out[eff] = [dict(d, count=c) for d, c in zip(own, counts)]
    return out


def design_team_cost(designs: list[dict], overhead: float) -> float:
    """The team's cost as the run computes it (`fitness.team_cost`), from each design's
    recorded cost (the run's catalog) and its distinct species."""
    robot = torch.tensor([float(d["cost"]) for d in designs for _ in range(int(d["count"]))])
    species = torch.tensor(len({d["species"] for d in designs if int(d["count"]) > 0}))
    return float(team_cost(robot, torch.ones_like(robot, dtype=torch.bool), species, overhead))


def cat(genomes: list[Population]) -> Population:
    """`Population.cat` of genomes whose trees may differ in length (NOP-padded to the longest)."""
    length = max(g.bt.shape[1] for g in genomes)
    return Population.cat([dataclasses.replace(
        g, bt=torch.nn.functional.pad(g.bt, (0, length - g.bt.shape[1]), value=bt.NOP))
        for g in genomes])


def evaluate(run: Path, window: int, every: int, envs: int, seed: int) -> dict:
    cfg = read_config(run)
    if cfg.budget is None:
        raise SystemExit(f"error: {run} has no budget")
    scenario = run_scenario(run, cfg)
    teams = read_teams(run)
    if not teams:
        raise SystemExit(f"error: {run} has no best team in teams.jsonl")
    last = max(teams)
    gens = [g for g in range(last - window + 1, last + 1, every) if g in teams]
    items, genomes, slots, offset = [], [], [], 0
    for g in gens:
        for name, ds in variants(teams[g]["designs"]).items():
            genome, team = team_genome(ds, cfg.tag_length)
            items.append((g, name, design_team_cost(ds, scenario.species_overhead)))
            genomes.append(genome)
            slots.append(team + offset)
            offset += genome.size
    genome = cat(genomes)
    S = max(len(s) for s in slots)
    teams_t = torch.full((len(slots), S), -1, dtype=torch.long)
    for i, s in enumerate(slots):
        teams_t[i, :len(s)] = s
    sized = dataclasses.replace(scenario, num_robots=S)
    layouts = make_layouts(sized, envs, torch.Generator().manual_seed(seed))
    V = len(items)
    team_rows = teams_t.repeat_interleave(envs, 0)               # [V * envs, S]
    layout_ids = torch.arange(envs).repeat(V)
    params = WorldParams.for_scenario(scenario)
    ticks = cfg.ticks or scenario.episode_ticks
    with torch.no_grad():
        m = simulate_teams(team_rows, genome, bt.build_tables(genome.bt), layout_ids, layouts,
                           params, ticks, catalog=scenario.hardware)
    raw = raw_fitness(m, cfg.fitness_weights).reshape(V, envs).mean(1)
    delivered = (m["delivered_individual"] + m["delivered_collab"]).reshape(V, envs).mean(1)
    rows = []
    for (g, name, cost), f, d in zip(items, raw.tolist(), delivered.tolist()):
        p = float(budget_penalty(torch.tensor(cost), cfg.budget, cfg.lam))
        rows.append({"generation": g, "variant": name, "raw": round(f, 1), "cost": round(cost, 1),
                     "penalty": round(p, 3), "score": round(f * p, 1),
                     "deliveries": round(d, 2)})
    return summarise(run, cfg, rows)


def summarise(run: Path, cfg, rows: list[dict]) -> dict:
    by_gen: dict[int, dict] = {}
    for r in rows:
        by_gen.setdefault(r["generation"], {})[r["variant"]] = r
    paired = []
    for g, v in sorted(by_gen.items()):
        ones = [v[e] for e in ("suction", "pincher") if e in v]
        if not ones:
            continue                                   # a one-effector team already
        best = max(ones, key=lambda r: r["raw"])      # R is against the better copy's F_raw
        t = v["team"]
        paired.append({"generation": g, "team": t, "one": best,
                       "ratio": round(t["raw"] / best["raw"], 3),
                       "break_even": round(best["penalty"] / t["penalty"], 3),
                       "team_wins": t["score"] > max(r["score"] for r in ones)})
    med = lambda xs: round(statistics.median(xs), 3) if xs else None  # noqa: E731
    return {"run": str(run), "budget": cfg.budget, "lam": cfg.lam, "rows": rows,
            "paired": paired,
            "median": {"ratio": med([p["ratio"] for p in paired]),
                       "team_raw": med([p["team"]["raw"] for p in paired]),
                       "team_cost": med([p["team"]["cost"] for p in paired]),
                       "team_deliveries": med([p["team"]["deliveries"] for p in paired]),
                       "one_raw": med([p["one"]["raw"] for p in paired]),
                       "one_cost": med([p["one"]["cost"] for p in paired]),
                       "one_deliveries": med([p["one"]["deliveries"] for p in paired]),
                       "team_penalty": med([p["team"]["penalty"] for p in paired]),
                       "one_penalty": med([p["one"]["penalty"] for p in paired]),
                       "break_even": med([p["break_even"] for p in paired])},
            "team_wins": sum(p["team_wins"] for p in paired),
            "teams_compared": len(paired)}


#: The paper's Table III: budget -> (best fitness, team cost, individual deliveries,
#: collaborative deliveries, average energy used %, species).
PAPER_TABLE_III = {2500: (125.2, 2500, 4, 0, 53.8, 1), 3000: (154.1, 3000, 8, 2, 41.0, 2),
                   4000: (182.9, 3800, 10, 0, 67.6, 2), 5000: (211.6, 5100, 10, 1, 36.4, 3),
                   6000: (224.7, 6110, 11, 1, 46.9, 3), 8000: (244.4, 7880, 9, 2, 42.4, 4)}


def paper_raw_bounds(individual: int, collab: int, energy_used: float,
                     packages: int = 20) -> tuple[float, float]:
    """(lower, upper) bound of F_raw under the paper's formula and weights for a team of the
    paper's table (see the module text for what each bound assumes)."""
    def raw(grips: float, picked: float, proximity: float, closeness: float) -> float:
        m = {"delivered_individual": individual, "delivered_collab": collab,
             "grips_delivered": grips * collab, "picked_individual": picked,
             "picked_collab": 0.0, "mean_final_energy": 100.0 - energy_used,
             "proximity": proximity, "closeness": closeness}
        return float(raw_fitness({k: torch.tensor(float(v)) for k, v in m.items()}))
    return (raw(0, individual + collab, 0.0, 0.0), raw(2, packages, 10.0, 1.0))


def paper_table() -> list[dict]:
    """Every row's team of Table III scored at every budget of the table (bounds)."""
    out = []
    for row, (fit, cost, ind, col, used, sp) in PAPER_TABLE_III.items():
        lo, hi = paper_raw_bounds(ind, col, used)
        at = {}
        for b in PAPER_TABLE_III:
            p = float(budget_penalty(torch.tensor(float(cost)), float(b), 0.001))
            at[b] = [round(lo * p, 1), round(hi * p, 1)]
        out.append({"row": row, "species": sp, "cost": cost, "deliveries": ind + col,
                    "paper_fitness": fit, "raw": [round(lo, 1), round(hi, 1)], "at_budget": at})
    return out


def print_paper(rows: list[dict]) -> None:
    budgets = list(PAPER_TABLE_III)
    print("| Table III row (species, cost, deliveries) | paper's fitness | F_raw bounds | "
          + " | ".join(f"scored at ${b:,}" for b in budgets) + " |")
    print("|---" * (3 + len(budgets)) + "|")
    for r in rows:
        cells = [f"{lo:.0f}-{hi:.0f}" for lo, hi in r["at_budget"].values()]
        print(f"| ${r['row']:,} ({r['species']}, ${r['cost']:,}, {r['deliveries']}) "
              f"| {r['paper_fitness']} | {r['raw'][0]:.0f}-{r['raw'][1]:.0f} | "
              + " | ".join(cells) + " |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="*", type=Path)
    ap.add_argument("--paper", action="store_true", help="the arithmetic on the paper's Table III")
    ap.add_argument("--window", type=int, default=50)
    ap.add_argument("--every", type=int, default=5)
    ap.add_argument("--envs", type=int, default=32)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    torch.set_grad_enabled(False)
    if a.paper:
        rows = paper_table()
        print_paper(rows)
        if a.json:
            a.json.write_text(json.dumps(rows, indent=1) + "\n")
        return
    if not a.runs:
        ap.error("give run directories, or --paper")
    for name in ("window", "every", "envs"):
        if getattr(a, name) < 1:
            ap.error(f"--{name} must be at least 1, got {getattr(a, name)}")
    try:
        out = [evaluate(r, a.window, a.every, a.envs, a.seed) for r in a.runs]
    except RunError as e:
        raise SystemExit(f"error: {e}") from None
    print("| run | budget | team: F_raw, cost, P_budget, deliveries "
          "| one effector: F_raw, cost, P_budget, deliveries | R = F_raw ratio "
          "| R below which one effector wins | team wins |")
    print("|---|---|---|---|---|---|---|")
    for o in out:
        m = o["median"]
        print(f"| {Path(o['run']).name} | {o['budget']:,.0f} "
              f"| {m['team_raw']:.0f}, ${m['team_cost']:,.0f}, {m['team_penalty']}, "
              f"{m['team_deliveries']} | {m['one_raw']:.0f}, ${m['one_cost']:,.0f}, "
              f"{m['one_penalty']}, {m['one_deliveries']} | {m['ratio']} | {m['break_even']} "
              f"| {o['team_wins']} of {o['teams_compared']} |")
    if a.json:
        a.json.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
