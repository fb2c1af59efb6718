"""How far do a run's individuals lie from their species' prototype?

    python experiments/2026-12-01-settling-speciation-v02/species_spread.py RUN_DIR [RUN_DIR ...] [--checkpoint FILE]

Reads each run's checkpoint: the population waiting to be speciated (the children of the last
finished generation, with the species they inherited) and the prototypes of that generation.
Prints, over all children and with each run's own distance (its d_hw with or without tiers):
the median distance D to the prototype of the inherited species, its terms (tag, hw, bt, tool,
size), and the share of children that lie beyond delta - w_tool of it, where one effector flip
more would found a species, and beyond delta itself (they found or join another species at
the next speciation); and the share of children that one effector flip would make found a
species (no prototype of the generation within delta of the flipped child), and how far each
prototype is from its nearest other prototype apart from the effector (median over prototypes
of the smallest D minus its tool term). Used in
docs/RESULTS.md ("The mechanism").
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import torch

from swarmcode_torch.coevo.population import Population
from swarmcode_torch.app.runs import load_checkpoint, read_checkpoint, read_config
from swarmcode_torch.coevo.speciation import distance_terms


def spread(run: Path, checkpoint: str | None = None) -> dict:
    cfg = read_config(run)
    ck = read_checkpoint(run / checkpoint) if checkpoint else load_checkpoint(run)
    w = cfg.distance_weights
    pop = Population.from_state_dict(ck["genome"])
    proto = Population.from_state_dict(ck["proto"])
    ids = ck["proto_ids"].tolist()
    hint = ck["species_hint"].tolist()
    rows = [i for i, s in enumerate(hint) if s in ids]
    col = torch.tensor([ids.index(hint[i]) for i in rows])
    terms = distance_terms(pop.index(torch.tensor(rows)), proto, w)
    mine = {k: v[torch.arange(len(rows)), col] for k, v in terms.items()}
    d = sum(mine.values())
    # what one effector flip would do to each child: found a species (no prototype within delta)
    flipped = Population.from_state_dict({**ck["genome"], "effector": 1 - pop.effector})
    d_flip = sum(distance_terms(flipped.index(torch.tensor(rows)), proto, w).values())
    # how far each species is from its nearest other species, apart from the effector
    pt = distance_terms(proto, proto, w)
    apart = (sum(pt.values()) - pt["tool"]).fill_diagonal_(float("inf")).min(1).values
    apart = apart[torch.isfinite(apart)]
    return {"run": run.name, "generation": int(ck["generation"]), "children": len(rows),
            "flip_founds": float((d_flip.min(1).values > cfg.delta).float().mean()),
            "prototype_D_but_tool": statistics.median(apart.tolist()) if apart.numel() else
            float("nan"),
            "species": len(ids),
            "median_D": statistics.median(d.tolist()),
            **{f"median_{k}": statistics.median(v.tolist()) for k, v in mine.items()},
            "beyond_delta_minus_w_tool": float((d > cfg.delta - w.w_tool).float().mean()),
            "beyond_delta": float((d > cfg.delta).float().mean())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--checkpoint", help="another checkpoint file of each run directory, e.g. a "
                    "copy kept at some generation (default: checkpoint.pt)")
    a = ap.parse_args()
    for run in a.runs:
        s = spread(run, a.checkpoint)
        print(f"{s['run']} gen {s['generation']}: median D {s['median_D']:.3f} "
              f"(tag {s['median_tag']:.3f} hw {s['median_hw']:.3f} bt {s['median_bt']:.3f} "
              f"tool {s['median_tool']:.3f} size {s['median_size']:.3f}); beyond "
              f"delta - w_tool {100 * s['beyond_delta_minus_w_tool']:.0f} %, beyond delta "
              f"{100 * s['beyond_delta']:.0f} % of {s['children']} children; an effector flip "
              f"would found a species for {100 * s['flip_founds']:.0f} % ({s['species']} species, "
              f"nearest other prototype at D - tool {s['prototype_D_but_tool']:.3f} (median))")


if __name__ == "__main__":
    main()
