"""Benchmark the behavior-tree module: build_tables per generation, lookup / interpret per tick.

Writes benchmarks/results/bt_<device>.json. Example:
    python benchmarks/bench_bt.py --device cpu --programs 100 --length 32 --robots 8000
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from collections.abc import Callable
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import RESULTS_DIR, now, run_metadata, write_json  # noqa: E402

from swarmcode_torch.sim import bt  # noqa: E402


def timed(
    fn: Callable[[], object], device: torch.device, repeats: int, warmup: int = 2
) -> list[float]:
    """Wall-clock seconds of repeats calls of fn, after warmup calls (synchronizing on CUDA)."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t0 = now(device)
        fn()
        times.append(now(device) - t0)
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
    parser.add_argument(
        "--threads", type=int, default=None, help="torch CPU threads (default: torch's)"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--out", default=None, help="output JSON (default benchmarks/results/bt_<device>.json)"
    )
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    device = torch.device(args.device)

    g = torch.Generator().manual_seed(args.seed)
    templates = [
        bt.template_tensor(n, args.length)
        for n in bt.TEMPLATES
        if len(bt.TEMPLATES[n]) <= args.length
    ]
    programs = torch.cat(
        [torch.stack(templates), bt.random_programs(args.programs, args.length, g)]
    )
    programs = programs[: args.programs].to(device)
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
        **run_metadata(device),
        "programs": args.programs,
        "length": args.length,
        "robots": args.robots,
        "max_leaves": int(
            ((programs >= bt.COND_HAS_PACKAGE) & (programs <= bt.ACT_MOVE_TO_RANDOM_PACK))
            .sum(1)
            .max()
        ),
        "build_tables": summary(build),
        "compute_jumps": summary(jumps),
        "lookup_per_tick": summary(lookup),
        "interpret_per_tick": summary(interp),
        "lookup_equals_interpret": agree,
    }
    write_json(result, Path(args.out) if args.out else RESULTS_DIR / f"bt_{device.type}.json")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
