"""Who founds the species of a run: continue a checkpoint (or snapshot) for some generations and
classify every founder by what separates it from its parent species' prototype.

    python experiments/2026-12-01-settling-speciation-v02/founders.py CHECKPOINT GENERATIONS [--json OUT]

The run continues eagerly (no torch.compile) from CHECKPOINT with its saved config; every new
species of every generation is recorded: the generation, its parent species (the founder's
species hint), whether its effector differs from that species' prototype (an effector flip),
the terms of its distance D to that prototype (tag, hw, bt, tool, size: `distance_terms`) and
its D to the nearest previous prototype. Prints the founding rate, the share of flips, the
median of each term and the first 40 founders. Used in docs/RESULTS.md ("What founds species
after generation 100").
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics

import torch
from pathlib import Path

from swarmcode_torch.app.runs import config_from_dict, read_checkpoint
from swarmcode_torch.coevo import evolve as E
from swarmcode_torch.coevo.speciation import distance, distance_terms


def founders(checkpoint: str, generations: int) -> list[dict]:
    d = read_checkpoint(Path(checkpoint))
    cfg = dataclasses.replace(config_from_dict(d["config"], checkpoint),
                              generations=d["generation"] + generations, compile=False)
    ev = E.Evolution.from_checkpoint(d, cfg)
    w = ev.ctx.speciation.weights
    found: list[dict] = []

    def spy(e: E.AfterSpeciation) -> None:
        st, r = e.state, e.speciation
        genome, hint, prev_proto, next_id = st.genome, st.species_hint, st.proto, st.next_species_id
        prev = st.proto_ids.tolist()
        for row in r.proto_index[r.proto_ids >= next_id].tolist():
            g = genome.index(slice(row, row + 1))
            item = {"generation": ev.state.generation, "parent_species": int(hint[row])}
            if prev_proto is not None and item["parent_species"] in prev:
                j = prev.index(item["parent_species"])
                pp = prev_proto.index(slice(j, j + 1))
                terms = {k: float(v) for k, v in distance_terms(g, pp, w).items()}
                item.update(terms=terms, distance=sum(terms.values()),
                            flip=int(g.effector[0]) != int(pp.effector[0]))
            if prev_proto is not None and len(prev):
                item["nearest"] = float(distance(g, prev_proto, w).min())
            found.append(item)

    ev.hooks.after_speciation.append(spy)
    while not ev.done:
        ev.step()
    return found


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("checkpoint")
    ap.add_argument("generations", type=int)
    ap.add_argument("--json", help="write every founder's record here")
    args = ap.parse_args()
    torch.set_num_threads(1)
    rec = founders(args.checkpoint, args.generations)
    flips = sum(bool(r.get("flip")) for r in rec)
    print(f"{len(rec)} founders in {args.generations} generations "
          f"({len(rec) / args.generations:.2f} a generation), {flips} effector flips")
    with_terms = [r for r in rec if "terms" in r]
    for k in ("tag", "hw", "bt", "tool", "size"):
        v = [r["terms"][k] for r in with_terms]
        if v:
            print(f"  {k:5s} median {statistics.median(v):.3f}")
    for r in rec[:40]:
        t = " ".join(f"{k}={v:.2f}" for k, v in r.get("terms", {}).items())
        print(f"  gen {r['generation']} from species {r['parent_species']} "
              f"{'flip' if r.get('flip') else '    '} D={r.get('distance', float('nan')):.3f} {t}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rec, f, indent=1)


if __name__ == "__main__":
    main()
