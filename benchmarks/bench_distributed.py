"""Sweeps and sharded evaluation on Ray: wall times, what a generation ships, the driver's share.

1. A sweep of `--sweep-budgets` x `--sweep-seeds` small runs (8 by default), once per
   `--sweep-workers` value: each `swarmcode-torch sweep` process is timed from start to exit
   (with --workers > 1 that includes starting a local Ray cluster, timed alone as
   `ray_start_seconds`); the tables of all of them must be identical.
2. Generations of one configuration (`scenario:swarm:population`), evaluated in this process
   and in `--shards` shards on Ray actors (local cluster), each mode from the same state after
   `--warmup` generations, so every mode computes the same generations (checked: the same
   populations and metrics). Per mode: seconds per generation, and for the shards the bytes of
   the pickled arguments sent and results received per generation and where the driver waited.
   In-process, the generation is split into its parts (speciation; the evaluation's plan:
   partners, teams and layouts; the simulation: behavior-tree tables and rollout; scoring;
   reproduction; the rest: best-team record and metrics): all but the simulation stays in the
   driver when the evaluation is sharded.

    python benchmarks/bench_distributed.py --device cpu
    python benchmarks/bench_distributed.py --device cuda --configs four-niche:20:50 --shards 1,2,4,8
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import int_list, median, now, parse_configs, run_metadata, write_json  # noqa: E402

from swarmcode_torch.app.distributed import ShardedEvaluator  # noqa: E402
from swarmcode_torch.coevo import evaluation, evolve  # noqa: E402
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.evolve import Evolution  # noqa: E402


# ------------------------------------------------------------------ 1. sweeps
def bench_sweep(args, workers: int, out: Path) -> dict:
    cmd = [
        sys.executable,
        "-m",
        "swarmcode_torch",
        "sweep",
        "--budgets",
        args.sweep_budgets,
        "--seeds",
        args.sweep_seeds,
        "--scenario",
        args.sweep_scenario,
        "--population",
        str(args.sweep_population),
        "--swarm-size",
        str(args.sweep_swarm),
        "--trials",
        "1",
        "--ticks",
        str(args.sweep_ticks),
        "--generations",
        str(args.sweep_generations),
        "--no-compile",
        "--device",
        "cpu",
        "--out",
        str(out),
        "--workers",
        str(workers),
    ]
    env = dict(os.environ)
    if args.threads:  # the in-process sweep's torch threads (Ray tasks: --cpus-per-run)
        env["OMP_NUM_THREADS"] = str(args.threads)
    t = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t
    if r.returncode != 0:
        raise SystemExit(f"sweep with --workers {workers} failed:\n{r.stdout}\n{r.stderr}")
    runs = len(args.sweep_budgets.split(",")) * len(args.sweep_seeds.split(","))
    return {
        "workers": workers,
        "runs": runs,
        "wall_seconds": wall,
        "command": " ".join(cmd[1:]).replace(str(out), "OUT"),
        "table_csv": (out / "table.csv").read_text(),
    }


def ray_start_seconds() -> float:
    code = (
        "import time, ray; t = time.perf_counter(); ray.init(include_dashboard=False); "
        "ray.shutdown(); print(time.perf_counter() - t)"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(r.stdout.split()[-1])


# ------------------------------------------------------------------ 2. generations
class _Timers:
    """Wall time of the parts of a generation, by wrapping the functions `generation` and
    `evaluate` call (device synchronised)."""

    PARTS = {
        "speciation": (evolve, "speciate"),
        "reproduction": (evolve, "reproduce"),
        "eval_plan": (evolve, "plan_evaluation"),
        "simulation": (evaluation, "simulate_batch"),
        "scoring": (evaluation, "score_plan"),
    }

    def __init__(self, device: torch.device):
        self.device = device
        self.seconds: dict[str, float] = defaultdict(float)
        self.saved = {}

    def __enter__(self):
        for name, (mod, attr) in self.PARTS.items():
            fn = getattr(mod, attr)
            self.saved[name] = fn

            def timed(*a, _fn=fn, _name=name, **kw):
                t = now(self.device)
                out = _fn(*a, **kw)
                self.seconds[_name] += now(self.device) - t
                return out

            setattr(mod, attr, timed)
        return self

    def __exit__(self, *exc):
        for name, (mod, attr) in self.PARTS.items():
            setattr(mod, attr, self.saved[name])


def _same_state(a, b) -> bool:
    ga, gb = a.genome.state_dict(), b.genome.state_dict()
    return (
        all(torch.equal(ga[k], gb[k]) for k in ga)
        and torch.equal(a.fitness, b.fitness)
        and torch.equal(a.rng_state, b.rng_state)
    )


def _timed_generations(ev: Evolution, args, device: torch.device):
    """Runs `args.generations` generations: their seconds, numeric fields of each
    `GenerationResult` (as sorted JSON, less the timings: the `*seconds` fields), states after each, and simulation seconds."""
    gen_s, metrics, states, rollout_s = [], [], [], []
    for _ in range(args.generations):
        t = now(device)
        m = ev.step()
        gen_s.append(now(device) - t)
        rollout_s.append(m.sim_seconds)
        metrics.append(
            json.dumps(
                {
                    k: v
                    for k, v in vars(m).items()
                    if isinstance(v, (int, float)) and not k.endswith("seconds")
                },
                sort_keys=True,
            )
        )
        states.append(ev.state)
    return gen_s, metrics, states, rollout_s


def _in_process_fields(timers: _Timers, gen_s, rollout_s, args) -> dict:
    """The in-process mode's parts of a generation and the driver's share."""
    parts = {k: v / args.generations for k, v in timers.seconds.items()}
    parts["rest"] = median(gen_s) - sum(parts.values())
    # the simulation is the behavior-tree tables and the rollout
    parts["simulation_rollout"] = median(rollout_s)
    driver = median(gen_s) - parts["simulation"]
    return {
        "parts_seconds_per_generation": parts,
        "driver_seconds_per_generation": driver,
        "driver_share": driver / median(gen_s),
    }


def _sharded_fields(evaluator, gen_s, same: bool) -> dict:
    """A sharded mode's traffic and waits per generation, from the evaluator's stats."""
    st = evaluator.stats
    n = len(st)
    return {
        "bytes_sent_per_generation": sum(s["bytes_sent"] for s in st) / n,
        "bytes_received_per_generation": sum(s["bytes_received"] for s in st) / n,
        "evaluations_per_shard": st[0]["evaluations"],
        "pack_and_send_seconds": median([s["send_seconds"] for s in st]),
        "wait_seconds": median([s["wait_seconds"] for s in st]),
        "unpack_seconds": median([s["gather_seconds"] for s in st]),
        "slowest_shard_sim_seconds": median([max(s["shard_sim_seconds"]) for s in st]),
        "driver_seconds_per_generation": median(gen_s) - median([s["wait_seconds"] for s in st]),
        "where": evaluator.where,
        "same_as_in_process": same,
    }


def _print_mode(name: str, pop: int, row: dict) -> None:
    print(
        f"{name} pop {pop}: {row['mode']}: {row['seconds_per_generation']:.3f} s/gen"
        + (
            f", {row['bytes_sent_per_generation'] / 1024:.1f} KiB sent, "
            f"{row['bytes_received_per_generation'] / 1024:.1f} KiB back, same: "
            f"{row['same_as_in_process']}"
            if row["shards"]
            else f", driver share {100 * row['driver_share']:.0f} %"
        ),
        flush=True,
    )


def bench_generations(name: str, swarm: int, pop: int, args, device: torch.device) -> dict:
    cfg = SwarmCoDeConfig(
        scenario=name,
        swarm_size=swarm,
        population=pop,
        trials=args.trials,
        ticks=args.ticks,
        generations=10_000,
        device=str(device),
        compile=args.compile,
        seed=0,
        budget=args.budget,
    )
    ev = Evolution(cfg)
    for _ in range(args.warmup):
        ev.step()
    start = ev.state
    modes: list[dict] = []
    reference_states = None
    for shards in [0] + args.shards:  # 0: in this process
        ev.state = start
        evaluator = None
        if shards:
            evaluator = ShardedEvaluator(ev.ctx, shards, args.cpus_per_shard)
            ev.ctx.evaluator = evaluator
            ev.step()  # the actors' first generation: not timed
            ev.state = start
            evaluator.stats.clear()
        timers = _Timers(device)
        with timers if not shards else _NoTimers():
            gen_s, metrics, states, rollout_s = _timed_generations(ev, args, device)
        row = {
            "mode": "in process" if not shards else f"{shards} shards on Ray",
            "shards": shards,
            "seconds_per_generation": median(gen_s),
            "all_generation_seconds": gen_s,
        }
        if not shards:
            reference_states, reference_metrics = states, metrics
            row.update(_in_process_fields(timers, gen_s, rollout_s, args))
        else:
            same = (
                all(_same_state(a, b) for a, b in zip(states, reference_states))
                and metrics == reference_metrics
            )
            row.update(_sharded_fields(evaluator, gen_s, same))
            ev.ctx.evaluator = None
            evaluator.close()
        modes.append(row)
        _print_mode(name, pop, row)
    return {
        "scenario": name,
        "swarm_size": swarm,
        "population": pop,
        "trials": args.trials,
        "ticks": ev.ctx.eval_cfg.ticks,
        "envs": 2 * pop * args.trials,
        "tick": ev.ctx.tick_mode,
        "warmup_generations": args.warmup,
        "timed_generations": args.generations,
        "modes": modes,
    }


class _NoTimers:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--configs", default="four-niche:20:32", help="scenario:swarm:population,...")
    ap.add_argument("--trials", type=int, default=2)
    ap.add_argument("--ticks", type=int, default=60, help="episode length [scenario's]")
    ap.add_argument("--budget", type=float, default=3000.0)
    ap.add_argument("--compile", action=argparse.BooleanOptionalAction, default=False)
    ap.add_argument("--warmup", type=int, default=1, help="in-process generations first")
    ap.add_argument("--generations", type=int, default=2, help="timed generations per mode")
    ap.add_argument("--shards", type=int_list, default=[1, 2])
    ap.add_argument("--cpus-per-shard", type=float, default=1.0)
    ap.add_argument("--sweep-workers", type=int_list, default=[1, 2])
    ap.add_argument("--sweep-budgets", default="300,500,800,1200")
    ap.add_argument("--sweep-seeds", default="0,1")
    ap.add_argument("--sweep-scenario", default="four-niche")
    ap.add_argument("--sweep-population", type=int, default=8)
    ap.add_argument("--sweep-swarm", type=int, default=4)
    ap.add_argument("--sweep-ticks", type=int, default=20)
    ap.add_argument("--sweep-generations", type=int, default=5)
    ap.add_argument(
        "--threads",
        type=int,
        default=None,
        help="torch CPU threads of this process and of the in-process sweep",
    )
    ap.add_argument("--notes", default=None, help="a note stored in the JSON")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    out = args.out or Path(__file__).parent / "results" / f"distributed_{device.type}.json"
    result = {**run_metadata(device), "notes": args.notes}

    tmp = Path(tempfile.mkdtemp(prefix="bench-distributed-"))
    try:
        sweeps = [bench_sweep(args, w, tmp / f"sweep-{w}") for w in args.sweep_workers]
        for s in sweeps:
            print(
                f"sweep of {s['runs']} runs, --workers {s['workers']}: {s['wall_seconds']:.1f} s",
                flush=True,
            )
        result["sweep"] = {
            "runs": [{k: v for k, v in s.items() if k != "table_csv"} for s in sweeps],
            "tables_identical": len({s["table_csv"] for s in sweeps}) == 1,
        }
        if any(w > 1 for w in args.sweep_workers):
            result["sweep"]["ray_start_seconds"] = ray_start_seconds()
        write_json(result, out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    import ray

    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    cpus = max(2, int(max(args.shards) * args.cpus_per_shard))
    ray.init(num_cpus=cpus, include_dashboard=False, log_to_driver=False)
    try:
        result["generations"] = []
        for name, swarm, pop in parse_configs(args.configs):
            result["generations"].append(bench_generations(name, swarm, pop, args, device))
            write_json(result, out)
    finally:
        ray.shutdown()
    write_json(result, out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
