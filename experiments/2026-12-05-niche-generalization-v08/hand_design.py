"""Can a class be delivered at all? The class alone in its world (arena, obstacles, episode),
a team of N robots of one hand design (the class's effector, radius R, every tier 3, torque
and battery operating points 1) running the fetch-and-return tree of `niche_value.py`, on
seeds 0 .. seeds - 1.

    python experiments/2026-12-05-niche-generalization-v08/hand_design.py WORLD.toml CLASS \
        --radii 0.4,0.44 --robots 4 [--seeds 4] [--json OUT]

Prints, per radius, the design's mass, drive force, what the lift rule needs for the class's
heaviest package, and the packages delivered per episode.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from niche_value import fetch_deliveries, hand

from swarmcode_torch.app.team_eval import team_rows
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.population import genome_phenotype
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.state import WorldParams


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("world")
    p.add_argument("cls", type=int)
    p.add_argument("--radii", required=True)
    p.add_argument("--robots", type=int, required=True)
    p.add_argument("--seeds", type=int, default=4)
    p.add_argument("--json")
    a = p.parse_args()
    world = load_scenario(a.world)
    c = world.packages[a.cls]
    params = WorldParams.for_scenario(world)
    rows = []
    for r in (float(x) for x in a.radii.split(",")):
        genome, _ = team_rows([hand(c, r, a.robots)], SwarmCoDeConfig().tag_length)
        ph = genome_phenotype(genome, world.hardware)
        delivered = fetch_deliveries(world, a.cls, r, a.robots, a.seeds)
        row = {
            "world": world.name, "class": a.cls, "label": c.label, "distance": list(c.distance),
            "robots": a.robots, "radius": r, "mass": round(float(ph.mass[0]), 2),
            "force": round(float(ph.force[0]), 1),
            "force_needed_heaviest": round(
                params.lift_force * (float(ph.mass[0]) + c.mass[1] / len(c.grips)), 1
            ),
            "delivered_per_episode": delivered,
            "count": c.count,
        }  # fmt: skip
        print(json.dumps(row), flush=True)
        rows.append(row)
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
