"""Where a run's best team lost a niche, and what the species of that niche did before.

    python experiments/2026-12-01-settling-speciation-v02/niche_losses.py RUN[@FROM] [RUN[@FROM] ...] [--before 15]

For every generation (from FROM on) at which a capability (a niche: the set of the scenario's
package classes a design can lift, as teams.jsonl records it) leaves the best team and does not
come back within 5 generations, prints the species that held that niche in the best team in the
`--before` generations before, each with its size in the population generation by generation
(the checkpoint's history) and the generation it died. The best team holds every species of the
population in runs with every species a partner (`partners_per_niche = "all"`, the default
before 0.4; docs/RESULTS.md), so its designs name each species' niche; with one partner per
niche a duplicate is in no team and is not listed. Used in docs/RESULTS.md ("How a niche is
lost", "One partner per niche").
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from swarmcode_torch.app.runs import load_checkpoint


def niche_losses(run: Path, start: int = 0, before: int = 15) -> list[dict]:
    teams = {}
    for line in open(run / "teams.jsonl"):
        try:
            r = json.loads(line)
            teams[r["generation"]] = r
        except (ValueError, KeyError):
            continue
    sizes = {h["generation"]: h["population"] for h in load_checkpoint(run)["history"]}
    gens = sorted(teams)
    niche = {}                                    # (generation, species) -> capability
    caps = {}
    for g in gens:
        caps[g] = set()
        for d in teams[g]["designs"]:
            c = tuple(d.get("capability") or ())
            niche[(g, d["species"])] = c
            caps[g].add(c)
    out = []
    for prev, g in zip(gens, gens[1:]):
        if g < start:
            continue
        for c in sorted(caps[prev] - caps[g]):
            if any(c in caps.get(h, set()) for h in range(g, g + 5)):
                continue
            species = sorted({s for (h, s), cc in niche.items() if cc == c and g - before <= h < g})
            rows = []
            for s in species:
                span = [h for h in range(g - before, g + 1) if h in sizes]
                died = next((h for h in span if s not in sizes[h] and s in sizes.get(h - 1, {})),
                            None)
                rows.append({"species": s, "sizes": [sizes[h].get(s, 0) for h in span],
                             "died": died})
            out.append({"generation": g, "niche": list(c), "species": rows})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", metavar="RUN[@FROM]")
    ap.add_argument("--before", type=int, default=15)
    ap.add_argument("--json", help="write the records here")
    args = ap.parse_args()
    found = {}
    for arg in args.runs:
        path, _, start = arg.partition("@")
        found[path] = niche_losses(Path(path), int(start or 0), args.before)
        for loss in found[path]:
            print(f"{Path(path).name} generation {loss['generation']}: niche {loss['niche']} "
                  f"lost; {len(loss['species'])} species held it in the {args.before} before")
            for s in loss["species"]:
                print(f"    species {s['species']}: sizes {s['sizes']}, died at {s['died']}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(found, f, indent=1)


if __name__ == "__main__":
    main()
