"""Benchmark the behavior-tree module: build_tables per generation, lookup / interpret per tick.

Writes benchmarks/results/bt_<device>.json. Example:
    python benchmarks/bench_bt.py --device cpu --programs 100 --length 32 --robots 8000
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from swarmcode_torch import bt  # noqa: E402


def git_commit() -> str:
    """The repository's HEAD commit, or "unknown"."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True,
                             cwd=Path(__file__).resolve().parent)
        return out.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def device_name(device: torch.device) -> str:
    """A human-readable name of the device."""
    if device.type == "cuda":
        return torch.cuda.get_device_name(device)
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def timed(fn: Callable[[], object], device: torch.device, repeats: int, warmup: int = 2) -> list[float]:
    """Wall-clock seconds of repeats calls of fn, after warmup calls (synchronizing on CUDA)."""
    def sync() -> None:
        if device.type == "cuda":
            torch.cuda.synchronize(device)

    for _ in range(warmup):
        fn()
    sync()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        sync()
        times.append(time.perf_counter() - t0)
    return times


def summary(times: list[float]) -> dict[str, float]:
    """Median and min of a list of seconds, in milliseconds."""
    return {"median_ms": 1e3 * statistics.median(times), "min_ms": 1e3 * min(times)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    parser.add_argument("--programs", type=int, default=100)
    parser.add_argument("--length", type=int, default=32)
    parser.add_argument("--robots", type=int, default=8000)
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None,
                        help="output JSON (default benchmarks/results/bt_<device>.json)")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    device = torch.device(args.device)

    g = torch.Generator().manual_seed(args.seed)
    templates = [bt.template_tensor(n, args.length) for n in bt.TEMPLATES
                 if len(bt.TEMPLATES[n]) <= args.length]
    programs = torch.cat([torch.stack(templates), bt.random_programs(args.programs, args.length, g)])
    programs = programs[:args.programs].to(device)
    prog_idx = torch.randint(0, args.programs, (args.robots,), generator=g).to(device)
    leaf_status = torch.randint(0, 3, (args.robots, bt.NUM_OPCODES), generator=g)
    leaf_status[:, 2:6] %= 2  # conditions return SUCCESS / FAILURE only
    leaf_status = leaf_status.to(device)

    build = timed(lambda: bt.build_tables(programs), device, max(3, args.repeats // 2), warmup=1)
    tables = bt.build_tables(programs)
    jumps_all = bt.compute_jumps(programs)
    robot_ops, robot_jumps = programs[prog_idx], jumps_all[prog_idx]
    jumps = timed(lambda: bt.compute_jumps(programs), device, args.repeats)
    lookup = timed(lambda: bt.lookup(tables, prog_idx, leaf_status), device, 10 * args.repeats)
    interp = timed(lambda: bt.interpret(robot_ops, robot_jumps, leaf_status), device, args.repeats)

    want = bt.interpret(robot_ops, robot_jumps, leaf_status)
    got = bt.lookup(tables, prog_idx, leaf_status)
    agree = all(torch.equal(w, x) for w, x in zip(want, got))

    result = {
        "device": str(device),
        "device_name": device_name(device),
        "torch": torch.__version__,
        "threads": torch.get_num_threads(),
        "git_commit": git_commit(),
        "command": " ".join([sys.executable, *sys.argv]),
        "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "programs": args.programs,
        "length": args.length,
        "robots": args.robots,
        "max_leaves": int(((programs >= bt.COND_HAS_PACKAGE) & (programs <= bt.ACT_MOVE_TO_RANDOM_PACK))
                          .sum(1).max()),
        "build_tables": summary(build),
        "compute_jumps": summary(jumps),
        "lookup_per_tick": summary(lookup),
        "interpret_per_tick": summary(interp),
        "lookup_equals_interpret": agree,
    }
    out = Path(args.out) if args.out else \
        Path(__file__).resolve().parent / "results" / f"bt_{device.type}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
