"""Wall time of `swarmcode-torch replay` (the GIF) and `replay --html` (the page), as a user
runs them: each command its own process, start-up and imports included, the median of
`--repeats`; and, in process, `analysis.replay_run` alone. With `--reference` the same again
with ``SWARMCODE_TICK=reference`` (the eager Python tick records the episodes); with `--before
DIR` the commands of another checkout too. The configurations take turns, repeat by repeat.

Without `--run`, the README's first run is made first (`evolve --scenario budget --budget 4000
--generations 20 --population 30 --seed SEED`, into a temporary folder).

    git worktree add /tmp/before <older commit>
    python benchmarks/bench_replay.py --seed 1 --reference --before /tmp/before
    python benchmarks/bench_replay.py --run runs/budget__b4000__0__<time> --repeats 5
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(1, str(ROOT))  # in process: this tree's swarmcode_torch, not an installed one
from common import RESULTS_DIR, run_metadata, write_json  # noqa: E402

EVOLVE = ["--scenario", "budget", "--budget", "4000", "--generations", "20", "--population", "30"]


def _env(reference: bool, root: Path = ROOT) -> dict:
    env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("SWARMCODE_TICK", None)
    if reference:
        env["SWARMCODE_TICK"] = "reference"
    return env


def make_run(logdir: Path, seed: int) -> Path:
    cmd = [sys.executable, "-m", "swarmcode_torch", "evolve", *EVOLVE, "--seed", str(seed)]
    subprocess.run(
        [*cmd, "--logdir", str(logdir)],
        check=True,
        capture_output=True,
        env=_env(False),
        cwd=str(ROOT),
    )
    (run,) = [p for p in logdir.iterdir() if p.is_dir()]
    return run


def replay_once(run: Path, out: Path, html: bool, reference: bool, root: Path) -> tuple:
    """(seconds, stdout) of one `replay` command in its own process."""
    cmd = [sys.executable, "-m", "swarmcode_torch", "replay", str(run), "--out", str(out)]
    cmd += ["--html"] if html else []
    t0 = time.perf_counter()
    # run from the tree's folder: `python -m` puts the working directory first on the path
    res = subprocess.run(
        cmd, capture_output=True, text=True, env=_env(reference, root), cwd=str(root)
    )
    seconds = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {res.stderr or res.stdout}")
    return seconds, res.stdout


def in_process_seconds(run: Path, out: Path, html: bool, reference: bool) -> float:
    from swarmcode_torch.app.analysis import replay_run

    old = os.environ.pop("SWARMCODE_TICK", None)
    if reference:
        os.environ["SWARMCODE_TICK"] = "reference"
    try:
        t0 = time.perf_counter()
        replay_run(run, out=out, html=html)
        return round(time.perf_counter() - t0, 3)
    finally:
        os.environ.pop("SWARMCODE_TICK", None)
        if old is not None:
            os.environ["SWARMCODE_TICK"] = old


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", type=Path, default=None, help="a run directory to replay")
    ap.add_argument("--seed", type=int, default=0, help="the seed of the run made without --run")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--reference", action="store_true", help="also time the Python tick's replay")
    ap.add_argument("--threads", type=int, default=None, help="torch CPU threads (in process)")
    ap.add_argument(
        "--before",
        type=Path,
        default=None,
        help="another checkout (e.g. a worktree of an older commit) whose `replay` is timed in "
        "turn with this one's",
    )
    ap.add_argument("--out", type=Path, default=RESULTS_DIR / "replay_cpu.json")
    args = ap.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        run = args.run if args.run is not None else make_run(tmp / "runs", args.seed)
        made = (
            None
            if args.run is not None
            else f"swarmcode-torch evolve {' '.join(EVOLVE)} --seed {args.seed}"
        )
        # (tree, tick) configurations, timed in turn repeat by repeat, so that a change in the
        # machine's load falls on all of them alike
        configs = [("this", ROOT, False)]
        configs += [("this", ROOT, True)] if args.reference else []
        configs += [("before", args.before, False)] if args.before is not None else []
        times: dict = {}
        for _ in range(args.repeats):
            for name, root, reference in configs:
                for html in (False, True):
                    out = tmp / f"{name}-{int(reference)}-team.{'html' if html else 'gif'}"
                    sec, text = replay_once(run, out, html, reference, root)
                    key = (name, reference, html)
                    times.setdefault(key, []).append((sec, os.getloadavg()[0]))
                    times[key + ("out",)] = (text, out.stat().st_size)
        rows = []
        for name, root, reference in configs:
            for html in (False, True):
                ts = times[(name, reference, html)]
                text, size = times[(name, reference, html, "out")]
                row = {
                    "what": "page" if html else "gif",
                    "tree": name,
                    "root": str(root),
                    "tick": "reference" if reference else "default",
                    "command": f"swarmcode-torch replay RUN{' --html' if html else ''}",
                    "seconds": round(statistics.median(t for t, _ in ts), 3),
                    "all_seconds": [round(t, 3) for t, _ in ts],
                    "load_average_after": [round(x, 2) for _, x in ts],
                    "bytes": size,
                    "output": text.strip().splitlines(),
                }
                if name == "this":
                    out = tmp / f"inproc.{'html' if html else 'gif'}"
                    row["in_process_seconds"] = in_process_seconds(run, out, html, reference)
                rows.append(row)
                print(f"{row['what']:4s} {name:6s} {row['tick']:9s} {row['seconds']:6.2f} s, "
                      f"{row['bytes']} bytes")  # fmt: skip
    meta = run_metadata(torch.device("cpu"))
    write_json({**meta, "run": str(args.run) if args.run else made, "results": rows}, args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
