"""What is a missing niche worth to the team? The last best team of a run (its teams.jsonl)
scored on fresh seeds as evolved, then with k of its largest species' robots swapped for a hand
design that lifts the missing class (the class's effector, radius R, every tier 3, torque and
battery operating points 1, a fetch-and-return tree), and, as the control for the tree, the
team's own hardware with every design given that tree.

    python experiments/2026-12-05-niche-generalization-v08/niche_value.py RUN_DIR CLASS \
        --radius R [--seeds 20] [--json OUT]

The same seeds for every variant (1000 .. 1000 + seeds - 1), so the differences are paired.
If the team scores no better with the class than without it, the fitness does not ask for that
niche in this world, and a run that leaves it empty is not losing it.
"""

from __future__ import annotations

import argparse
import copy
import json
from dataclasses import replace
from pathlib import Path

import torch

from swarmcode_torch.app.team_eval import draw_layouts, run_episodes, score_team, team_rows
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.worlds import FETCH as _FETCH

#: carrying: to the base and drop there; else at a package: pick it up; else go to one (the
#: generator's reach check runs the same tree)
FETCH = list(_FETCH)


def hand(c, radius: float, count: int, species: int = 0) -> dict:
    """The hand design for package class `c`: its first grip's effector, radius `radius`, every
    tier 3, torque and battery operating points 1, the fetch tree; `count` robots."""
    return dict(
        species=species, effector="pincher" if c.grips[0] else "suction", radius=radius,
        chassis_tier=3, battery_tier=3, motor_tier=3, torque_point=1.0, battery_point=1.0,
        bt=FETCH, count=count,
    )  # fmt: skip


def fetch_deliveries(world, cls: int, radius: float, robots: int, layouts: int = 4) -> float:
    """Mean packages of class `cls` delivered per episode, the class alone in `world`, by
    `robots` robots of the hand design of radius `radius`, on layouts of seeds 0 .. layouts - 1."""
    c = world.packages[cls]
    alone = replace(world, packages=(c,))
    cfg = SwarmCoDeConfig()
    genome, team = team_rows([hand(c, radius, robots)], cfg.tag_length)
    lay = draw_layouts(alone, int(team.numel()), list(range(layouts)))
    ep = run_episodes(
        genome, torch.tensor([0]), team.repeat(layouts, 1), lay, torch.arange(layouts), alone,
        cfg, world.episode_ticks, torch.device("cpu"),
    )  # fmt: skip
    return float(ep.delivered.sum(1).float().mean())


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("run")
    p.add_argument("cls", type=int)
    p.add_argument("--radius", type=float, required=True)
    p.add_argument("--seeds", type=int, default=20)
    p.add_argument("--json")
    a = p.parse_args()
    run = Path(a.run)
    world = load_scenario(str(run / "scenario.toml"))
    c = world.packages[a.cls]
    team = [json.loads(x) for x in (run / "teams.jsonl").read_text().splitlines()][-1]["designs"]
    cfg = SwarmCoDeConfig()
    seeds = list(range(1000, 1000 + a.seeds))

    def score(designs: list[dict]) -> dict:
        s = score_team(designs, cfg, world, seeds, world.episode_ticks)
        return {"mean": round(s.mean, 1), "low": round(s.low, 1), "high": round(s.high, 1)}

    rows = {"world": world.name, "class": a.cls, "label": c.label, "run": run.name}
    rows["as evolved"] = score(team)
    big = max(range(len(team)), key=lambda i: team[i]["count"])
    for k in (1, 2, 3, 4, 6):
        t = copy.deepcopy(team)
        t[big]["count"] -= k
        t.append(hand(c, a.radius, k, species=-1))
        rows[f"+{k} robots for the class"] = score(t)
    t = copy.deepcopy(team)
    for d in t:
        d["bt"] = FETCH
    rows["own hardware, fetch tree (control)"] = score(t)
    for k, v in rows.items():
        print(f"{k}: {v}")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
