"""What each species' members score, generation by generation: continue a run from a checkpoint
(or snapshot) and record, for every species, its size, its niche (the capability of its
prototype), the share of its members whose focal team did not beat its baseline (gated: their
fitness is multiplied by p_marginal), their mean fitness and their offspring quota.

    python experiments/2026-12-01-settling-speciation-v02/sisters.py CHECKPOINT GENERATIONS [--set KEY=VALUE ...] [--trials N]
        [--json OUT]

The run continues with its saved config (compiled as it was, so that a continuation of an
unchanged run repeats it) and the settings given (`--trials`: trials per evaluation). Used in docs/RESULTS.md ("How a niche is
lost") to show what happens to two species of one niche.
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import torch
from pathlib import Path

from swarmcode_torch.app.runs import config_from_dict, read_checkpoint
from swarmcode_torch.app.settings import parse_settings
from swarmcode_torch.coevo import evolve as E
from swarmcode_torch.coevo.population import genome_phenotype
from swarmcode_torch.sim.state import capabilities


def continue_and_record(checkpoint: str, generations: int, settings: dict) -> list[dict]:
    d = read_checkpoint(Path(checkpoint))
    cfg = config_from_dict({**d["config"], **settings}, checkpoint)
    cfg = dataclasses.replace(cfg, generations=d["generation"] + generations)
    ev = E.Evolution.from_checkpoint(d, cfg)
    ctx = ev.ctx
    rows: list[dict] = []

    def spy_repro(e: E.AfterReproduction) -> None:
        genome, fit, res = e.state.genome, e.fitness, e.evaluation
        species, proto_ids, proto_index = (e.speciation.species, e.speciation.proto_ids,
                                           e.speciation.proto_index)
        hint = e.next_state.species_hint
        can = capabilities(genome_phenotype(genome.index(proto_index), ctx.scenario.hardware),
                           ctx.scenario, ctx.params)
        gated = res.focal - res.baseline <= 0
        for j, sid in enumerate(proto_ids.tolist()):
            m = species == sid
            n = int(m.sum())
            if n == 0:
                continue
            rows.append({
                "generation": ev.state.generation, "species": sid, "size": n,
                "niche": [c for c, ok in enumerate(can[j].tolist()) if ok],
                "effector": int(genome.effector[proto_index[j]]),
                "gated": float(gated[m].float().mean()),
                "fitness": float(fit[m].float().mean()),
                "quota": int((hint == sid).sum())})

    ev.hooks.after_reproduction.append(spy_repro)
    while not ev.done:
        ev.step()
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("checkpoint")
    ap.add_argument("generations", type=int)
    ap.add_argument("--set", dest="settings", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--trials", type=int, help="trials per evaluation (default: the run's)")
    ap.add_argument("--json", help="write the records here")
    args = ap.parse_args()
    torch.set_num_threads(1)
    settings = parse_settings(args.settings)
    if args.trials is not None:
        settings["trials"] = args.trials
    rows = continue_and_record(args.checkpoint, args.generations, settings)
    print("gen  species  niche  size  gated  mean fitness  quota")
    for r in rows:
        print(f"{r['generation']:4d}  {r['species']:6d}  {str(r['niche']):6s} {r['size']:4d}  "
              f"{r['gated']:5.2f}  {r['fitness']:12.1f}  {r['quota']:5d}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
