"""What a replay explains, beyond its one episode and its pictures: each design's pick-ups and
deliveries and where the arenas part, as lines the command prints (`explain_lines`, from the
page's data), and the focal individual's marginal contribution over several environments
(`seed_marginals`, `replay --seeds N`): its team and its baseline team
(`replay_page.focal_and_baseline` of the replay's seed, the same two teams everywhere) in the
environments of seeds SEED, SEED + 1, ..., SEED + N - 1, all in one batch on the CPU's tick,
each episode scored as the page scores its one."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import torch

from ..coevo.evaluation import simulate_teams, team_scores
from ..coevo.fitness import team_cost
from ..coevo.population import genome_phenotype
from ..sim import bt
from ..sim.layout import Layout, make_layouts
from ..sim.runtime import tick_function
from ..sim.scenario import Scenario
from ..sim.state import WorldParams
from .episodes import CREDIT_KINDS, team_genome
from .replay_teams import focal_and_baseline, species_count

#: The most environments `replay --seeds` takes (each is two episodes).
MAX_REPLAY_SEEDS = 1000


def seed_marginals(
    designs: Sequence[dict],
    scenario: Scenario,
    cfg,
    seed: int,
    seeds: int,
    ticks: int | None = None,
) -> dict:
    """{"seeds": [first, last], "focal": [...], "baseline": [...], "marginal": [...], "mean",
    "sd"}: the two teams' scores and their difference in each environment, the mean and sample
    standard deviation of the differences (sd None for one environment)."""

    genome, _ = team_genome(designs, cfg.tag_length)
    _, team, base, _ = focal_and_baseline(designs, seed)
    ticks = scenario.episode_ticks if ticks is None else int(ticks)
    world = dataclasses.replace(scenario, num_robots=int(team.numel()))
    parts = [make_layouts(world, 1, torch.Generator().manual_seed(seed + k)) for k in range(seeds)]
    layouts = Layout(*(torch.cat(xs) for xs in zip(*parts)))
    step_fn, _ = tick_function(torch.device("cpu"), compile=False)
    with torch.no_grad():
        m = simulate_teams(
            torch.stack([team, base]).repeat_interleave(seeds, 0),
            genome,
            bt.build_tables(genome.bt),
            torch.arange(seeds).repeat(2),
            layouts,
            WorldParams.for_scenario(scenario),
            ticks,
            step_fn=step_fn,
            catalog=scenario.hardware,
        )
    row_cost = genome_phenotype(genome, scenario.hardware).cost
    costs = []
    for t in (team, base):
        present = t >= 0
        counts = torch.tensor([species_count(designs, t)])
        c = team_cost(row_cost[t.clamp_min(0)], present, counts, scenario.species_overhead)
        costs.append(float(c[0]))
    ecfg = cfg.evaluation(scenario.num_robots, scenario.episode_ticks)
    cost = torch.tensor(costs).repeat_interleave(seeds)
    score = team_scores(m, cost, ecfg).tolist()
    focal, baseline = score[:seeds], score[seeds:]
    diff = [f - b for f, b in zip(focal, baseline)]
    mean = sum(diff) / seeds
    sd = math.sqrt(sum((d - mean) ** 2 for d in diff) / (seeds - 1)) if seeds > 1 else None
    return {
        "seeds": [seed, seed + seeds - 1],
        "focal": focal,
        "baseline": baseline,
        "marginal": diff,
        "mean": mean,
        "sd": sd,
    }


def design_credits(data: dict, panel: str) -> list[list[int]]:
    """Per design, its robots' credits in a panel at the end ([design][kind], CREDIT_KINDS)."""
    p = data["panels"][panel]
    out = [[0] * len(CREDIT_KINDS) for _ in data["designs"]]
    c = p["credits"]
    for i in range(0, len(c), 4):
        d = p["robots"]["design"][c[i + 1]]
        if d >= 0:
            out[d][c[i + 3]] += 1
    return out


def explain_lines(data: dict) -> list[str]:
    """What the page explains, as lines to print: where the arenas part, and who delivered."""
    part = data["divergence"]
    if part is not None:
        d = data["panels"]["focal"]["robots"]["design"][part["robot"]]
        g = data["designs"][d]
        lines = [
            f"The arenas part at tick {part['tick']} of {data['ticks']}: robot {part['robot']} "
            f"(species {g['species']}, {g['effector']}), in a slot both teams share, stands more "
            f"than {data['divergence_eps'] * 1000:g} mm apart"
        ]
    elif data["shared_slots"] == 0:
        lines = ["The teams share no slot (the focal has no partner): no divergence to show"]
    else:
        lines = [f"The arenas never part in {data['ticks']} ticks"]
    sm = data.get("seed_marginals")
    if sm:
        n = len(sm["marginal"])
        sd = f", sd {sm['sd']:.1f}" if sm["sd"] is not None else ""
        lines.append(
            f"Marginal contribution over {n} environments (seeds {sm['seeds'][0]}-"
            f"{sm['seeds'][1]}): mean {sm['mean']:.1f}{sd}; in this one {data['marginal']:.1f}"
        )
    for name in ("focal", "baseline"):
        per = design_credits(data, name)
        shown = [
            f"species {data['designs'][d]['species']} {data['designs'][d]['effector']}: "
            f"{c[0] + c[1]} delivered, {c[2] + c[3]} picked up"
            for d, c in enumerate(per)
            if any(r == d for r in data["panels"][name]["robots"]["design"])
        ]
        lines.append(f"{name.capitalize()} arena, by design: " + ("; ".join(shown) or "no robot"))
    return lines
