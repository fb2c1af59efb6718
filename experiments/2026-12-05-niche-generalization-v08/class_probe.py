"""Can each package class of a world be delivered at all? One short run a class, on the world
with that class alone (the same arena, obstacles, swarm and episode), the default algorithm.

    python experiments/2026-12-05-niche-generalization-v08/class_probe.py WORLD.toml \
        [--generations 80] [--population 30] [--seed 0] [--classes 1,3] [--json OUT]

Prints, per class, its label and the best team's deliveries of it (the best run's highest
single-evaluation deliveries, and the last generation's), out of the class's count. A class
whose packages no team delivers in its own one-class world is one the full world's best team
cannot be asked to keep: the generator's niche count says who can lift it, not who can bring
it home within the episode.

    python experiments/2026-12-05-niche-generalization-v08/class_probe.py shares \
        --split train [--designs 100000] [--json OUT]

How rare the designs that lift each class are: of `--designs` random genomes (what generation 0
draws, `Population.random`), the share that lift the class's lightest and its heaviest package
by the simulator's lift rule (`sim.state.capabilities`, read here to *describe* the worlds,
never by the algorithm); beside it, per world, how many of the split's recorded runs (every
arm) kept every niche in the last 50 generations.

    python experiments/2026-12-05-niche-generalization-v08/class_probe.py audit \
        (--split train | --worlds W.toml ...) [--json OUT]

The world audit of PLAN.md (fixed before it met a test world): a world is flagged when a class
is a needle (its heaviest package lifted by fewer than 1 % of random designs) or a niche's own
class is out of reach (a full swarm of all-premium designs with the fetch tree, at the best of
three radii in its band, delivers fewer than half its packages on 4 layouts of the class alone).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace

from pathlib import Path

import torch

from niche_value import fetch_deliveries

import swarmcode_torch as sc
from swarmcode_torch.coevo.population import Population, genome_phenotype
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.state import WorldParams, capabilities

HERE = Path(__file__).parent


def probe(
    path: str, generations: int, population: int, seed: int, only: list[int] | None = None
) -> list[dict]:
    world = load_scenario(path)
    out = []
    for i, c in enumerate(world.packages):
        if only is not None and i not in only:
            continue
        alone = replace(world, name=f"{world.name}-class{i}", packages=(c,))
        r = sc.evolve(
            scenario=alone,
            generations=generations,
            population=population,
            seed=seed,
            logdir=None,
            progress=False,
            device="cpu",
        )
        key = "team/deliveries"
        best = max(h.get(key, 0.0) for h in r.history)
        last = r.history[-1].get(key, 0.0)
        row = {
            "world": world.name,
            "class": i,
            "label": c.label,
            "kind": c.kind,
            "count": c.count,
            "distance": list(c.distance),
            "best_deliveries": best,
            "last_deliveries": last,
            "best_fitness": max(h["fitness/best"] for h in r.history),
        }
        print(json.dumps(row), flush=True)
        out.append(row)
    return out


def lift_shares(world, designs: int, seed: int = 0) -> list[tuple[float, float]]:
    """Per class of `world`: the share of `designs` random genomes that lift its lightest and
    its heaviest package (each robot's share of a collaborative package)."""
    g = torch.Generator().manual_seed(seed)
    ph = genome_phenotype(Population.random(designs, 16, 8, g), world.hardware)
    params = WorldParams.for_scenario(world)
    out = []
    for c in world.packages:
        light = capabilities(ph, replace(world, packages=(c,)), params)[:, 0]
        heavy_class = replace(c, mass=(c.mass[1], c.mass[1]))
        heavy = capabilities(ph, replace(world, packages=(heavy_class,)), params)[:, 0]
        out.append((float(light.float().mean()), float(heavy.float().mean())))
    return out


def shares(split: str, designs: int) -> list[dict]:
    """One row a class of every world of `split`, with its world's kept runs over every arm."""
    rows = []
    for toml in sorted((HERE / "worlds" / split).glob("*.toml")):
        world = load_scenario(str(toml))
        runs = [
            json.loads(f.read_text())
            for f in sorted((HERE / "results" / split).glob(f"*/{world.name}__s*.json"))
        ]
        kept = sum(bool(r["kept_last"]) for r in runs)
        for i, (c, (lo, hi)) in enumerate(zip(world.packages, lift_shares(world, designs))):
            row = {
                "world": world.name,
                "class": i,
                "label": c.label,
                "share_lightest": round(lo, 5),
                "share_heaviest": round(hi, 5),
                "world_runs": len(runs),
                "world_kept": kept,
            }
            print(json.dumps(row), flush=True)
            rows.append(row)
    return rows


NEEDLE = 0.01  # a class lifted by fewer than this share of random designs is a needle
REACH = 0.5  # a niche's own class is out of reach below this share of its packages delivered


def own_classes(toml: Path) -> list[int]:
    """The classes of a generated world that are a niche's own ("# niche k: ...; only its robots
    lift these", the comment the generator writes above the class)."""
    out, k, last = [], -1, ""
    for line in toml.read_text().splitlines():
        if line.strip() == "[[packages]]":
            k += 1
            if last.startswith("# niche ") and "only its robots lift these" in last:
                out.append(k)
        if line.strip():
            last = line.strip()
    return out


def audit(split: str | None, designs: int = 100_000, paths: list[str] | None = None) -> list[dict]:
    """One row a world of `split` (or of `paths`, generated world files): its needle classes,
    its out-of-reach own classes (with the best fetch deliveries of each own class), flagged or
    not, and its recorded runs kept (none for `paths`)."""
    rows = []
    tomls = [Path(p) for p in paths] if paths else sorted((HERE / "worlds" / str(split)).glob("*.toml"))
    for toml in tomls:
        world = load_scenario(str(toml))
        shares_ = lift_shares(world, designs)
        needles = [i for i, (_, hi) in enumerate(shares_) if hi < NEEDLE]
        reach = {}
        for i in own_classes(toml):
            lo, hi = world.packages[i].radius_band
            radii = (lo + 0.01, (lo + hi) / 2, hi - 0.01)
            best = max(fetch_deliveries(world, i, r, world.num_robots) for r in radii)
            reach[i] = round(best, 2)
        far = [i for i, v in reach.items() if v < REACH * world.packages[i].count]
        runs = {}
        for f in sorted((HERE / "results" / str(split)).glob(f"*/{world.name}__s*.json")):
            r = json.loads(f.read_text())
            runs.setdefault(r["arm"], []).append(bool(r["kept_last"]))
        row = {
            "world": world.name,
            "classes": len(world.packages),
            "needles": needles,
            "out_of_reach": far,
            "own_class_deliveries": {str(k): v for k, v in reach.items()},
            "flagged": bool(needles or far),
            "kept": {arm: [sum(v), len(v)] for arm, v in sorted(runs.items())},
        }
        print(json.dumps(row), flush=True)
        rows.append(row)
    return rows


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "audit":
        q = argparse.ArgumentParser(prog="class_probe.py audit")
        w = q.add_mutually_exclusive_group(required=True)
        w.add_argument("--split", choices=("train", "test"))
        w.add_argument("--worlds", nargs="+", help="generated world files (swarmcode-torch world)")
        q.add_argument("--json")
        b = q.parse_args(sys.argv[2:])
        rows = audit(b.split, paths=b.worlds)
        if b.json:
            Path(b.json).write_text(json.dumps(rows, indent=1))
        return
    if len(sys.argv) > 1 and sys.argv[1] == "shares":
        q = argparse.ArgumentParser(prog="class_probe.py shares")
        q.add_argument("--split", choices=("train", "test"), required=True)
        q.add_argument("--designs", type=int, default=100_000)
        q.add_argument("--json")
        b = q.parse_args(sys.argv[2:])
        rows = shares(b.split, b.designs)
        if b.json:
            Path(b.json).write_text(json.dumps(rows, indent=1))
        return
    p = argparse.ArgumentParser()
    p.add_argument("world")
    p.add_argument("--generations", type=int, default=80)
    p.add_argument("--population", type=int, default=30)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json")
    p.add_argument("--classes", help="only these class indices, e.g. 1,3")
    a = p.parse_args()
    torch.set_num_threads(1)
    only = [int(x) for x in a.classes.split(",")] if a.classes else None
    rows = probe(a.world, a.generations, a.population, a.seed, only)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
