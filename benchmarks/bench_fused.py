"""Old against new, side by side in one run: the tick, a generation and the README's first
command, each measured in two worker processes (one per source tree) that take turns, so that
the load of a shared machine falls on both alike. Reports medians and new/old ratios.

    git worktree add /tmp/old380 380c00a
    python benchmarks/bench_fused.py --old /tmp/old380                # all three parts
    python benchmarks/bench_fused.py --old /tmp/old380 --parts tick --reps 7

Rows (issue #30's targets):
- tick: robot-ticks per second of E x N (default 300x20 four-niche, 64x200 swarm200) on
  `--tick-threads` threads (default 1); the old tree's tick compiled as in the issue
  (`torch.compile(step, dynamic=False, fullgraph=True)`), the new tree's default CPU tick
  (`sim.fused.FusedTicks`, all timed ticks in one call, as `rollout` runs them);
- generation: seconds per generation of four-niche, swarm 20, population 50, on `--gen-threads`
  threads (default 2); old with `compile=True`, new with its defaults (after 2 warm-up
  generations each);
- first: the README's first command, all in (a fresh process, start-up and any compile or
  build included): `swarmcode-torch evolve --scenario budget --budget 4000 --generations 20
  --population 30`, old and new with their defaults; the new tree once more with an empty
  extension cache (`TORCH_EXTENSIONS_DIR`), so the one-time C++ build is counted too.

Writes benchmarks/results/fused_cpu.json (device, torch, commit, command, load averages).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

REPO = Path(__file__).resolve().parents[1]

WORKER = r"""
import json, sys, time, torch
src = sys.argv[1]
sys.path.insert(0, src + "/benchmarks")
sys.path.insert(0, src)
from bench_sim import Workload, scenario_for
from swarmcode_torch.sim.step import step
from swarmcode_torch.sim.state import TickInputs
state = {}
for line in sys.stdin:
    cmd = json.loads(line)
    torch.set_num_threads(cmd.get("threads", 1))
    op = cmd["op"]
    t0 = time.perf_counter()
    if op == "tick_setup":
        w = Workload(scenario_for(cmd["N"]), cmd["E"], 0, 16, torch.device("cpu"))
        inp = TickInputs(w.layout, w.robots, w.compat, w.keys, w.tables)
        if cmd["mode"] == "compiled":
            torch._dynamo.reset()
            fn = torch.compile(step, dynamic=False, fullgraph=True)
            def ticks(s, n, fn=fn, inp=inp, p=w.params):
                for _ in range(n):
                    s = fn(s, *inp, p)
                return s
        else:
            from swarmcode_torch.sim.fused import FusedTicks
            f = FusedTicks()
            assert f.ready(), f.error
            def ticks(s, n, f=f, inp=inp, p=w.params):
                return f.run_ticks(s, inp, p, n)
        s = ticks(w.start(), 3)
        state.update(w=w, ticks=ticks, s=s)
        out = {}
    elif op == "tick_time":
        state["s"] = state["ticks"](state["s"], cmd["ticks"])
        out = {}
    elif op == "gen_setup":
        from swarmcode_torch.coevo.evolve import Evolution
        from swarmcode_torch.coevo.config import SwarmCoDeConfig
        cfg = SwarmCoDeConfig(scenario=cmd["scenario"], swarm_size=cmd["swarm"],
                              population=cmd["pop"], generations=1000, device="cpu",
                              compile=cmd["compile"], seed=0)
        ev = Evolution(cfg)
        for _ in range(cmd["warmup"]):
            ev.step()
        state["ev"] = ev
        out = {"tick_mode": ev.ctx.tick_mode}
    elif op == "gen_time":
        m = state["ev"].step()
        out = {"sim_seconds": m.sim_seconds}
    dt = time.perf_counter() - t0
    out["seconds"] = dt
    print(json.dumps(out), flush=True)
"""


class Worker:
    def __init__(self, src: Path, threads: int):
        env = dict(os.environ, PYTHONPATH=str(src), OMP_NUM_THREADS=str(threads))
        self.p = subprocess.Popen(
            [sys.executable, "-c", WORKER, str(src)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env=env,
            cwd=str(src),
        )

    def ask(self, **cmd) -> dict:
        self.p.stdin.write(json.dumps(cmd) + "\n")
        self.p.stdin.flush()
        line = self.p.stdout.readline()
        if not line:
            raise RuntimeError(f"worker died on {cmd}")
        return json.loads(line)

    def close(self):
        self.p.stdin.close()
        self.p.wait(timeout=60)


def load() -> float:
    return os.getloadavg()[0]


def median(xs):
    xs = sorted(xs)
    n = len(xs)
    return xs[n // 2] if n % 2 else 0.5 * (xs[n // 2 - 1] + xs[n // 2])


def bench_ticks(args, old: Path, new: Path) -> list[dict]:
    rows = []
    for cfg in args.tick_configs.split(","):
        E, N, T = (int(x) for x in cfg.split(":"))
        workers = {"old": Worker(old, args.tick_threads), "new": Worker(new, args.tick_threads)}
        try:
            setup = {
                k: w.ask(
                    op="tick_setup",
                    E=E,
                    N=N,
                    threads=args.tick_threads,
                    mode="compiled" if k == "old" else "fused",
                )["seconds"]
                for k, w in workers.items()
            }
            times = {"old": [], "new": []}
            loads = []
            for r in range(args.reps):
                order = ("old", "new") if r % 2 == 0 else ("new", "old")
                for k in order:
                    ticks = T if k == "old" else T * args.new_tick_factor
                    s = workers[k].ask(op="tick_time", ticks=ticks, threads=args.tick_threads)
                    times[k].append(s["seconds"] / ticks)
                loads.append(load())
        finally:
            for w in workers.values():
                w.close()
        rt = {k: E * N / median(v) for k, v in times.items()}
        row = {
            "workload": f"tick E={E} x N={N}",
            "E": E,
            "N": N,
            "threads": args.tick_threads,
            "old": "compiled (torch.compile fullgraph)",
            "new": "fused C++ tick",
            "setup_seconds": setup,
            "seconds_per_tick": {k: median(v) for k, v in times.items()},
            "all_seconds_per_tick": times,
            "robot_ticks_per_second": rt,
            "ratio_new_over_old": rt["new"] / rt["old"],
            "load_average": loads,
        }
        print(
            json.dumps(
                {
                    k: row[k]
                    for k in ("workload", "seconds_per_tick", "ratio_new_over_old", "load_average")
                }
            ),
            flush=True,
        )
        rows.append(row)
    return rows


def bench_generation(args, old: Path, new: Path) -> dict:
    workers = {"old": Worker(old, args.gen_threads), "new": Worker(new, args.gen_threads)}
    try:
        modes = {
            k: w.ask(
                op="gen_setup",
                scenario="four-niche",
                swarm=20,
                pop=50,
                warmup=2,
                compile=True if k == "old" else None,
                threads=args.gen_threads,
            )
            for k, w in workers.items()
        }
        times = {"old": [], "new": []}
        sims = {"old": [], "new": []}
        loads = []
        for r in range(args.gen_reps):
            for k in ("old", "new") if r % 2 == 0 else ("new", "old"):
                out = workers[k].ask(op="gen_time", threads=args.gen_threads)
                times[k].append(out["seconds"])
                sims[k].append(out["sim_seconds"])
            loads.append(load())
    finally:
        for w in workers.values():
            w.close()
    med = {k: median(v) for k, v in times.items()}
    row = {
        "workload": "generation four-niche swarm 20 population 50",
        "threads": args.gen_threads,
        "tick_mode": {k: v["tick_mode"] for k, v in modes.items()},
        "seconds_per_generation": med,
        "all_seconds": times,
        "sim_share": {k: sum(sims[k]) / sum(times[k]) for k in times},
        "ratio_old_over_new": med["old"] / med["new"],
        "load_average": loads,
    }
    print(
        json.dumps(
            {
                k: row[k]
                for k in (
                    "workload",
                    "seconds_per_generation",
                    "ratio_old_over_new",
                    "load_average",
                )
            }
        ),
        flush=True,
    )
    return row


FIRST = [
    "evolve",
    "--scenario",
    "budget",
    "--budget",
    "4000",
    "--generations",
    "20",
    "--population",
    "30",
]


def bench_first(args, old: Path, new: Path) -> dict:
    def run(src: Path, ext_dir: str | None) -> dict:
        with tempfile.TemporaryDirectory() as logdir:
            env = dict(os.environ, PYTHONPATH=str(src))
            env.pop("OMP_NUM_THREADS", None)  # as a user starts it: the defaults choose
            if ext_dir is not None:
                env["TORCH_EXTENSIONS_DIR"] = ext_dir
            l0 = load()
            t0 = time.perf_counter()
            r = subprocess.run(
                [sys.executable, "-m", "swarmcode_torch", *FIRST, "--logdir", logdir],
                env=env,
                cwd=logdir,
                capture_output=True,
                text=True,
            )
            dt = time.perf_counter() - t0
            if r.returncode != 0:
                raise RuntimeError(r.stdout[-2000:] + r.stderr[-2000:])
            summ = next(Path(logdir).glob("*/summary.json"))
            s = json.loads(summ.read_text())
            return {
                "seconds": dt,
                "load_average_before": l0,
                "load_average_after": load(),
                "tick": s.get("tick"),
                "best_fitness": s.get("best_fitness"),
                "team_cost": s.get("team_cost"),
                "deliveries": s.get("deliveries"),
            }

    out = {"command": "swarmcode-torch " + " ".join(FIRST)}
    if args.first_cold:
        with tempfile.TemporaryDirectory() as cold:
            out["new_cold_build"] = run(new, cold)
    if args.first_old:
        out["old"] = run(old, None)
    out["new"] = run(new, None)
    if args.first_old:
        out["ratio_old_over_new"] = out["old"]["seconds"] / out["new"]["seconds"]
    print(json.dumps(out), flush=True)
    return out


def main() -> None:
    import torch
    from common import RESULTS_DIR, run_metadata, write_json

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", type=Path, required=True, help="the old source tree (a worktree)")
    ap.add_argument("--new", type=Path, default=REPO, help="the new source tree [this one]")
    ap.add_argument("--parts", default="tick,generation,first")
    ap.add_argument(
        "--tick-configs",
        default="300:20:20,64:200:5",
        help="E:N:ticks of the old tick per timing (the new one runs --new-tick-factor "
        "times as many)",
    )
    ap.add_argument("--new-tick-factor", type=int, default=5)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--tick-threads", type=int, default=1)
    ap.add_argument("--gen-threads", type=int, default=2)
    ap.add_argument("--gen-reps", type=int, default=4)
    ap.add_argument(
        "--first-old",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="first: run the old tree's command too (it takes minutes)",
    )
    ap.add_argument(
        "--first-cold",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="first: run the new tree once more with an empty extension cache",
    )
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    meta = run_metadata(torch.device("cpu"))
    meta["old_commit"] = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=args.old, capture_output=True, text=True
    ).stdout.strip()
    meta["nice"] = os.nice(0)
    res = {"meta": meta, "rows": {}}
    parts = args.parts.split(",")
    path = args.out or RESULTS_DIR / "fused_cpu.json"
    if "tick" in parts:
        res["rows"]["tick"] = bench_ticks(args, args.old, args.new)
        write_json(res, path)
    if "generation" in parts:
        res["rows"]["generation"] = bench_generation(args, args.old, args.new)
        write_json(res, path)
    if "first" in parts:
        res["rows"]["first"] = bench_first(args, args.old, args.new)
    res["meta"]["load_average_at_end"] = load()
    write_json(res, path)
    print("wrote", path)


if __name__ == "__main__":
    main()
