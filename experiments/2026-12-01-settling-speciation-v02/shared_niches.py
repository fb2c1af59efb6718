"""How often a niche is shared by two species or more, and how large its species are: for
each generation of a window, the capability of each species in the best team (the best team
holds every species of the population where every species is a partner, `partners_per_niche
= "all"`, the default before 0.4: its designs name each species' niche; with one partner per
niche it does not, so the count is not valid there) and each species' size in the population
(the run's history).

    python experiments/2026-12-01-settling-speciation-v02/shared_niches.py RUN_DIR FROM TO [--json OUT]

Prints, over generations FROM to before TO: the niche-generations held by one species and by
more than one, the median size of a species alone in its niche, and in a shared niche the
median size of the largest species and of the others. A species whose designs in the best team
lift different sets of classes, or none, is left out. Used in docs/RESULTS.md ("How a niche is
lost").
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path

from swarmcode_torch.app.analysis import design_capabilities
from swarmcode_torch.app.runs import load_checkpoint, read_config, read_teams, run_scenario


def shared_niches(run: Path, start: int, end: int) -> dict:
    sizes = {h["generation"]: {int(k): v for k, v in h["population"].items()}
             for h in load_checkpoint(run)["history"]}
    teams = read_teams(run)
    scenario = run_scenario(run, read_config(run))
    lone, largest, others, shared = [], [], [], 0
    for g in range(start, end):
        if g not in teams or g not in sizes:
            continue
        caps: dict[int, set] = {}
        designs = teams[g]["designs"]
        for d, cap in zip(designs, design_capabilities(designs, scenario)):
            caps.setdefault(d["species"], set()).add(tuple(cap))
        niche: dict[tuple, list[int]] = {}
        for sid, cs in caps.items():
            if len(cs) == 1 and next(iter(cs)):
                niche.setdefault(next(iter(cs)), []).append(sizes[g].get(sid, 0))
        for members in niche.values():
            if len(members) == 1:
                lone.append(members[0])
            else:
                shared += 1
                members.sort(reverse=True)
                largest.append(members[0])
                others += members[1:]
    return {"run": run.name, "from": start, "to": end, "alone": len(lone), "shared": shared,
            "alone_size": _median(lone), "shared_largest_size": _median(largest),
            "shared_other_size": _median(others)}


def _median(values: list[int]) -> float | None:
    return statistics.median(values) if values else None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("start", type=int)
    ap.add_argument("end", type=int)
    ap.add_argument("--json")
    args = ap.parse_args()
    r = shared_niches(args.run, args.start, args.end)
    print(json.dumps(r))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(r, f, indent=1)


if __name__ == "__main__":
    main()
