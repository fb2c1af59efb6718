"""Seconds per SwarmCoDe generation, and the share spent in simulation, for the paper's setups.

Each configuration is `scenario:swarm_size:population`. The first `--warmup` generations
(which include torch.compile's compile time, reported separately) are not timed.

    python benchmarks/bench_generation.py --device cpu --configs four-niche:20:50 --generations 2
    python benchmarks/bench_generation.py --device cuda          # the issue's four setups
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import median, now, parse_configs, run_metadata, write_json  # noqa: E402
from swarmcode_torch.coevo.evolve import Evolution  # noqa: E402
from swarmcode_torch.coevo.config import SwarmCoDeConfig

DEFAULT_CONFIGS = "four-niche:20:50,budget:20:100,swarm200:200:50,swarm1000:1000:50"


def bench(name: str, swarm: int, pop: int, args, device: torch.device) -> dict:
    cfg = SwarmCoDeConfig(scenario=name, swarm_size=swarm, population=pop, trials=args.trials,
                       ticks=args.ticks, generations=args.warmup + args.generations,
                       device=str(device), compile=args.compile, seed=0,
                       cuda_graphs=args.cuda_graphs)
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(device)
    ev = Evolution(cfg)
    t0 = now(device)
    for _ in range(args.warmup):
        ev.step()
    warmup_s = now(device) - t0
    gen_s, eval_s, sim_s = [], [], []
    for _ in range(args.generations):
        t = now(device)
        m = ev.step()
        gen_s.append(now(device) - t)
        eval_s.append(m.eval_seconds)
        sim_s.append(m.sim_seconds)
    ticks = ev.ctx.eval_cfg.ticks
    envs = 2 * pop * args.trials
    row = {
        "scenario": name, "swarm_size": swarm, "population": pop, "trials": args.trials,
        "ticks": ticks, "envs": envs, "compile": ev.ctx.compiled,
        "cuda_graphs": ev.ctx.tick_mode.endswith("CUDA graphs"),
        "warmup_generations": args.warmup, "warmup_seconds": warmup_s,
        "seconds_per_generation": median(gen_s), "all_generation_seconds": gen_s,
        "sim_share": sum(sim_s) / sum(gen_s),
        "evaluation_share": sum(eval_s) / sum(gen_s),
        "robot_ticks_per_s": envs * swarm * ticks / median(sim_s),
        "minutes_per_500_generations": median(gen_s) * 500 / 60,
    }
    if device.type == "cuda":
        row["peak_memory_bytes"] = torch.cuda.max_memory_allocated(device)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--configs", default=DEFAULT_CONFIGS, help="scenario:swarm:population,...")
    ap.add_argument("--generations", type=int, default=3, help="timed generations")
    ap.add_argument("--warmup", type=int, default=1, help="untimed generations first")
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--ticks", type=int, default=None, help="episode length [scenario's]")
    ap.add_argument("--compile", action=argparse.BooleanOptionalAction, default=None,
                    help="torch.compile the tick [default: on CUDA only]")
    ap.add_argument("--cuda-graphs", action=argparse.BooleanOptionalAction, default=None,
                    help="replay the compiled tick as CUDA graphs (evolve's cuda_graphs key) "
                         "[default: as evolve, on where the tick runs compiled on CUDA]")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    device = torch.device(args.device)
    rows = []
    out = args.out or Path(__file__).parent / "results" / f"generation_{device.type}.json"
    for name, swarm, pop in parse_configs(args.configs):
        t = time.perf_counter()
        rows.append(bench(name, swarm, pop, args, device))
        r = rows[-1]
        print(f"{name} swarm {swarm} pop {pop}: {r['seconds_per_generation']:.2f} s/gen, "
              f"simulation {100 * r['sim_share']:.0f}%, evaluation {100 * r['evaluation_share']:.0f}%, "
              f"{r['robot_ticks_per_s'] / 1e6:.2f} M robot-ticks/s "
              f"(warm-up {r['warmup_seconds']:.1f} s; {time.perf_counter() - t:.0f} s total)",
              flush=True)
        write_json({**run_metadata(device), "results": rows}, out)  # keep what is done
    write_json({**run_metadata(device), "results": rows}, out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
