"""How many effector flips would found a species, in a run's final population.

    python experiments/2026-12-02-effector-rate-budget-v05/flip_share.py RUN [RUN ...] [--json OUT]

The final population of each run is speciated as the next generation would be (its saved
prototypes carried over); then every individual's effector is flipped, nothing else, and the
share of flipped copies farther than delta from every prototype is printed: the share of flips
that would found a species if a flip changed only the effector (a child's other mutations add to
its distance). Used in docs/RESULTS.md ("A rarer effector flip, now that a niche is kept").
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from swarmcode_torch.app.runs import config_from_dict, load_checkpoint
from swarmcode_torch.coevo.population import Population
from swarmcode_torch.coevo.speciation import distance, speciate


def flip_share(run: Path) -> dict:
    ck = load_checkpoint(run)
    cfg = config_from_dict(ck["config"], str(run))
    sp = cfg.speciation
    g = Population.from_state_dict(ck["genome"])
    proto = Population.from_state_dict(ck["proto"])
    r = speciate(g, ck["species_hint"], proto, ck["proto_ids"], ck["next_species_id"], sp.delta,
                 w=sp.weights)
    flipped = replace(g, effector=1 - g.effector)
    beyond = distance(flipped, g.index(r.proto_index), sp.weights).min(1).values > sp.delta
    return {"run": str(run), "generation": int(ck["generation"]),
            "species": int(r.proto_ids.numel()), "share_beyond": round(float(beyond.float().mean()), 3)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    rows = [flip_share(r) for r in a.runs]
    for row in rows:
        print(f"{row['run']}: generation {row['generation']}, {row['species']} species, "
              f"{row['share_beyond']:.2f} of flipped copies beyond delta")
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
