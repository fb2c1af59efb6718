"""Wall time of whole `swarmcode-torch evolve` runs: start-up, compile, every generation and the
reporters (TensorBoard, checkpoints, summary), as a user runs it.

Each configuration is `scenario:swarm_size:population`; each runs as its own process, one after
the other, for `--generations` generations. A run still going after `--time-limit` seconds is
interrupted (SIGINT: it writes its checkpoint); the row then has the generations it finished and
the wall time projected to all of them (wall x generations / finished).

    python benchmarks/bench_end_to_end.py --device cuda --configs four-niche:20:50,swarm200:200:50
    python benchmarks/bench_end_to_end.py --device cpu --configs four-niche:20:8 --generations 3
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import parse_configs, run_metadata, write_json  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def run_one(name: str, swarm: int, pop: int, args) -> dict:
    with tempfile.TemporaryDirectory() as logdir:
        cmd = [
            sys.executable,
            "-m",
            "swarmcode_torch.app.cli",
            "evolve",
            "--scenario",
            name,
            "--swarm-size",
            str(swarm),
            "--population",
            str(pop),
            "--generations",
            str(args.generations),
            "--seed",
            str(args.seed),
            "--device",
            args.device,
            "--logdir",
            logdir,
            "--render-every",
            "0",
            "--log-every",
            str(max(1, args.generations // 5)),
        ]
        for kv in args.set or []:
            cmd += ["--set", kv]
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        try:
            out, _ = proc.communicate(timeout=args.time_limit)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGINT)
            out, _ = proc.communicate()
        wall = time.perf_counter() - t0
        summaries = list(Path(logdir).glob("*/summary.json"))
        if proc.returncode not in (0, 130) or not summaries:
            tail = "\n".join(out.strip().splitlines()[-5:])
            raise SystemExit(f"{name}: evolve exited {proc.returncode}:\n{tail}")
        summary = json.loads(summaries[0].read_text())
    done = summary["generation"] + 1
    last = summary.get("last_generation", {})
    return {
        "scenario": name,
        "swarm_size": swarm,
        "population": pop,
        "generations": args.generations,
        "generations_done": done,
        "finished": done >= args.generations,
        "wall_seconds": wall,
        "wall_seconds_projected": wall * args.generations / done,
        "last_generation_seconds": last.get("perf/generation_seconds"),
        "tick": summary.get("tick"),
        "command": " ".join(cmd[1:]).replace(logdir, "LOGDIR"),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument(
        "--configs",
        default="four-niche:20:50,swarm200:200:50",
        help="scenario:swarm:population,...",
    )
    ap.add_argument("--generations", type=int, default=500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--time-limit",
        type=float,
        default=None,
        help="seconds per run before it is interrupted (then projected)",
    )
    ap.add_argument(
        "--set", action="append", metavar="KEY=VALUE", help="passed to evolve's --set (repeatable)"
    )
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    device = torch.device(args.device)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise SystemExit("--device cuda: no CUDA device here")
    out = args.out or Path(__file__).parent / "results" / f"end_to_end_{device.type}.json"
    rows = []
    for name, swarm, pop in parse_configs(args.configs):
        r = run_one(name, swarm, pop, args)
        rows.append(r)
        what = (
            ""
            if r["finished"]
            else f" (all {r['generations']}: {r['wall_seconds_projected']:.0f} s projected)"
        )
        print(
            f"{name} swarm {swarm} pop {pop}: {r['generations_done']} of {r['generations']} "
            f"generations in {r['wall_seconds']:.1f} s{what}, tick {r['tick']}",
            flush=True,
        )
        write_json({**run_metadata(device), "results": rows}, out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
