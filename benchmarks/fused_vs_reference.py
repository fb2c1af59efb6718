"""Do the fused C++ tick and the Python tick give the same results in distribution?

The two ticks agree to float rounding from any state (tests/sim/test_fused.py), but over an episode
of contact dynamics rounding differences grow, so runs are not bit for bit the same. This runs
the same short evolutions (one per seed) with each tick (`SWARMCODE_TICK=reference` / `fused`,
each in its own process) and puts their per-generation best fitness, species and deliveries
side by side, with the mean and spread over seeds.

    OMP_NUM_THREADS=1 python benchmarks/fused_vs_reference.py --seeds 0,1,2

Writes benchmarks/results/fused_vs_reference.json.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
REPO = Path(__file__).resolve().parents[1]

RUN = r"""
import json, sys, time
from swarmcode_torch.app import api
kw = json.loads(sys.argv[1])
t0 = time.perf_counter()
res = api.evolve(logdir=None, **kw)
keys = ("generation", "fitness/best", "fitness/mean", "species/count", "team/deliveries",
        "team/cost")
rows = [{k: r.get(k) for k in keys} for r in res.history]
print(json.dumps({"rows": rows, "seconds": time.perf_counter() - t0}))
"""


def main() -> None:
    import torch
    from common import RESULTS_DIR, run_metadata, write_json

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--scenario", default="four-niche")
    ap.add_argument("--generations", type=int, default=10)
    ap.add_argument("--population", type=int, default=20)
    ap.add_argument("--swarm-size", type=int, default=8)
    ap.add_argument("--trials", type=int, default=2)
    ap.add_argument("--ticks", type=int, default=300)
    ap.add_argument("--out", type=Path, default=RESULTS_DIR / "fused_vs_reference.json")
    args = ap.parse_args()
    out = {"meta": run_metadata(torch.device("cpu")), "runs": {}}
    for tick in ("reference", "fused"):
        for seed in (int(s) for s in args.seeds.split(",")):
            kw = dict(
                scenario=args.scenario,
                generations=args.generations,
                population=args.population,
                swarm_size=args.swarm_size,
                trials=args.trials,
                ticks=args.ticks,
                seed=seed,
                device="cpu",
            )
            env = dict(os.environ, SWARMCODE_TICK=tick, PYTHONPATH=str(REPO))
            r = subprocess.run(
                [sys.executable, "-c", RUN, json.dumps(kw)],
                env=env,
                capture_output=True,
                text=True,
                check=True,
            )
            out["runs"][f"{tick} seed {seed}"] = json.loads(r.stdout.strip().splitlines()[-1])
            print(tick, seed, out["runs"][f"{tick} seed {seed}"]["rows"][-1], flush=True)
    summary = {}
    for tick in ("reference", "fused"):
        finals = [v["rows"][-1] for k, v in out["runs"].items() if k.startswith(tick)]
        summary[tick] = {
            key: {
                "mean": statistics.mean(f[key] for f in finals),
                "sd": statistics.pstdev(f[key] for f in finals),
                "values": [f[key] for f in finals],
            }
            for key in ("fitness/best", "fitness/mean", "species/count", "team/deliveries")
        }
    out["final_generation"] = summary
    print(json.dumps(summary, indent=1))
    write_json(out, args.out)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
