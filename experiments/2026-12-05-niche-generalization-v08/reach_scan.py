"""How often the generator's default knobs draw a world with a niche out of reach: seeds 0-7 of
1-5 niches, each drawn without the reach check (`min_reach=0`) and with the default, timed.

    python experiments/2026-12-05-niche-generalization-v08/reach_scan.py [--json OUT]

Prints one line a world: niches, seed, the reach of each niche drawn without the check, whether
the default drew another world, and the seconds the default's draw took.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from swarmcode_torch.sim.worlds import generate_world, niche_reach


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--json")
    a = p.parse_args()
    rows = []
    for niches in range(1, 6):
        for seed in range(8):
            plain = generate_world(seed, niches=niches, min_reach=0.0)
            t0 = time.perf_counter()
            w = generate_world(seed, niches=niches)
            dt = time.perf_counter() - t0
            row = {
                "niches": niches,
                "seed": seed,
                "reach_without_check": [
                    round(niche_reach(plain.scenario, n), 4) for n in plain.niche_designs
                ],
                "redrawn": w.table != plain.table,
                "seconds": round(dt, 3),
            }
            print(json.dumps(row), flush=True)
            rows.append(row)
    n = sum(r["redrawn"] for r in rows)
    print(f"redrawn {n} of {len(rows)}")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
