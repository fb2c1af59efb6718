"""Does a change keep the results bit for bit? Run two fixed small CLI runs and the three
baselines with the code of one source tree, then compare two such outputs.

    git worktree add /tmp/before <commit>
    python benchmarks/same_results.py run --src /tmp/before --out /tmp/same/before
    python benchmarks/same_results.py run --src . --out /tmp/same/after
    python benchmarks/same_results.py compare /tmp/same/before /tmp/same/after

`run` works on any commit since the CLI existed (it tries the module paths of the 0.3 layout,
then those before it). `run --set KEY=VALUE` (repeatable) gives every run and baseline that
setting, e.g. to run a tree whose defaults have changed with the settings of an older one:
`--set partners_per_niche=all --set quota_size_exponent=none` are the defaults before 0.4. `compare` prints one line per file and exits 1 if any differs:
summary.json (less its timings), teams.jsonl, metrics.csv and TensorBoard scalars (less
perf/*), config.toml, checkpoint.pt (every tensor and value), and the baselines' per-generation
metrics (less seconds). CPU only; about a minute on 2 cores.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import operator
import os
import subprocess
import sys
from pathlib import Path

import tomllib

RUNS = (
    [
        "--scenario",
        "four-niche",
        "--population",
        "16",
        "--swarm-size",
        "6",
        "--trials",
        "2",
        "--ticks",
        "40",
        "--seed",
        "7",
        "--generations",
        "8",
        "--checkpoint-every",
        "3",
        "--render-every",
        "4",
        "--log-every",
        "4",
    ],
    [
        "--scenario",
        "budget",
        "--budget",
        "2500",
        "--population",
        "12",
        "--swarm-size",
        "5",
        "--trials",
        "1",
        "--ticks",
        "30",
        "--seed",
        "3",
        "--generations",
        "5",
        "--render-every",
        "0",
        "--set",
        "p_tag_flip=0.05",
    ],
)

BASELINES = """
import json, sys
try:
    from swarmcode_torch.coevo.config import SwarmCoDeConfig as C
except ImportError:
    from swarmcode_torch.evolve import EvolveConfig as C
from swarmcode_torch.baselines import make_algorithm
out = {}
for name in ("homogeneous-ga", "ccea", "swarmcode"):
    cfg = C(scenario="four-niche", population=12, swarm_size=6, trials=1, ticks=30, seed=5,
            generations=3, device="cpu", compile=False, **json.loads(sys.argv[2]))
    algo = make_algorithm(name, cfg)
    out[name] = [{k: v for k, v in algo.step().items()
                  if isinstance(v, (int, float)) and "seconds" not in k} for _ in range(3)]
json.dump(out, open(sys.argv[1], "w"), indent=1, sort_keys=True)
"""

UNTIMED_SUMMARY = {
    "wall_seconds",
    "seconds_per_generation",
    "elapsed_seconds",
    "software",
}  # versions, device name and commit (0.3.1): not a result


#: Config keys that one side of a comparison may lack by design: the settings removed in 0.7
#: (rejected experiments and keys that kept pre-0.2 behaviour for old runs; a config of 0.6
#: holds them, one of 0.7 does not) and the distance weights that 0.7 made settings (the
#: other way round). Such a key is left out of config.toml and of the checkpoint's config only
#: when one side lacks it; where both hold it, it is compared.
VERSION_KEYS = {
    "gate_margin",
    "quota_basis",
    "quota_inertia",
    "effector_flip",
    "d_hw_tiers",
    "bt_point_on_nodes",
    "merge_species",
    "evaluated_partners",
    "baseline_refill",
    "w_tag",
    "w_hw",
    "w_bt",
    "w_tool",
    "w_size",
    "gamma",
    # settings added off since (their default is the behaviour before them)
    "demote_far_after",
    "demote_after",
    "substitute_effector",
    "equal_quotas_until",
    "refound_source",
    "best_team_floor",
    "best_team_tie",
    "team_partners",
    "team_partners_margin",
    "knockout_credit",
    "knockout_floor",
    "knockout_pairs",
    "share_basis",
}


def _common_keys(x: dict, y: dict, prefix: str = "") -> tuple[dict, dict]:
    """x and y without the `VERSION_KEYS` (under `prefix`) that only one of them holds."""
    drop = {k for k in set(x) ^ set(y) if k.startswith(prefix) and k[len(prefix) :] in VERSION_KEYS}
    return (
        {k: v for k, v in x.items() if k not in drop},
        {k: v for k, v in y.items() if k not in drop},
    )


#: summary.json records added since 0.6 (not results): compared only when both trees write them.
ADDED_SUMMARY = {"stop"}  # why the run stopped (generations, max_time, patience)


def setting_value(text: str):
    """A --set value as the baselines' config takes it: none, a TOML-style number or boolean,
    else the string."""
    if text == "none":
        return None
    try:
        return json.loads(text)
    except ValueError:
        return text


def run(src: Path, out: Path, settings: list[str] = ()) -> None:
    out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PYTHONPATH": str(src.resolve())}
    out = out.resolve()
    where = subprocess.run(
        [sys.executable, "-c", "import swarmcode_torch; print(swarmcode_torch.__file__)"],
        env=env,
        capture_output=True,
        text=True,
        cwd=out,
        check=True,
    ).stdout
    if not Path(where.strip()).resolve().is_relative_to(src.resolve()):
        sys.exit(f"the package imports from {where.strip()}, not from --src {src}")
    for args in RUNS:
        cmd = [
            sys.executable,
            "-m",
            "swarmcode_torch",
            "evolve",
            *args,
            "--device",
            "cpu",
            "--no-compile",
            "--logdir",
            str(out),
        ]
        for kv in settings:
            cmd += ["--set", kv]
        # cwd=out: `python -m` and `-c` put the working directory first on sys.path, so run
        # from a checkout's root they would import its package instead of `src`'s
        r = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=out)
        if r.returncode:
            sys.exit(f"{' '.join(cmd)} failed:\n{r.stdout[-2000:]}\n{r.stderr[-2000:]}")
    given = {}
    for kv in settings:
        key, sep, value = kv.partition("=")
        if not sep:
            sys.exit(f"--set {kv}: expected KEY=VALUE")
        given[key] = setting_value(value)
    subprocess.run(
        [sys.executable, "-c", BASELINES, str(out / "baselines.json"), json.dumps(given)],
        env=env,
        check=True,
        cwd=out,
    )
    print(f"wrote {out}")


def _untimed(x):
    if isinstance(x, dict):
        return {
            k: _untimed(v)
            for k, v in x.items()
            if k not in UNTIMED_SUMMARY and not k.startswith("perf/")
        }
    if isinstance(x, list):
        return [_untimed(v) for v in x]
    return "nan" if isinstance(x, float) and math.isnan(x) else x


def _scalars(run_dir: Path) -> dict:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(run_dir), size_guidance={"scalars": 0})
    acc.Reload()
    return {
        t: [(e.step, _untimed(e.value)) for e in acc.Scalars(t)]
        for t in acc.Tags()["scalars"]
        if not t.startswith("perf/")
    }


def _checkpoint(run_dir: Path) -> dict:
    import torch

    def flat(x, path=""):
        if isinstance(x, dict):
            for k, v in x.items():
                yield from flat(v, f"{path}.{k}")
        elif isinstance(x, torch.Tensor):
            yield path, (x.dtype, tuple(x.shape), x.flatten().tolist())
        else:
            yield path, json.dumps(x, sort_keys=True, default=str)

    d = torch.load(run_dir / "checkpoint.pt", weights_only=True)
    if isinstance(d, dict) and "best" in d and "app" not in d:
        # a checkpoint written before the best team became the application's record (0.8):
        # the same record, read where the newer layout keeps it
        d["app"] = {"best": d.pop("best")}
    return dict(flat(d))


def compare(a: Path, b: Path) -> int:
    def runs(root: Path) -> dict[str, Path]:
        return {p.name.split("__")[0]: p for p in root.iterdir() if p.is_dir()}

    ra, rb = runs(a), runs(b)
    different = 0
    for name in sorted(ra):
        x, y = ra[name], rb.get(name)
        checks = {
            "summary.json": lambda d: _untimed(json.loads((d / "summary.json").read_text())),
            "teams.jsonl": lambda d: (d / "teams.jsonl").read_text(),
            "metrics.csv": lambda d: _untimed(list(csv.DictReader(open(d / "metrics.csv")))),
            "tensorboard scalars": _scalars,
            "config.toml": lambda d: tomllib.loads((d / "config.toml").read_text()),
            "checkpoint.pt": _checkpoint,
        }
        for what, read in checks.items():
            va, vb = read(x), read(y) if y is not None else None
            if what == "summary.json" and vb is not None:
                for key in ADDED_SUMMARY:  # a record one of the two versions does not write
                    if (key in va) != (key in vb):
                        va.pop(key, None)
                        vb.pop(key, None)
            if vb is None:
                same = False
            elif what == "config.toml":
                same = operator.eq(*_common_keys(va, vb))
            elif what == "checkpoint.pt":
                same = operator.eq(*_common_keys(va, vb, ".config."))
            else:
                same = va == vb
            different += not same
            print(f"{name:12s} {what:20s} {'identical' if same else 'DIFFERENT'}")
    same = json.loads((a / "baselines.json").read_text()) == json.loads(
        (b / "baselines.json").read_text()
    )
    different += not same
    print(f"{'baselines':12s} {'metrics':20s} {'identical' if same else 'DIFFERENT'}")
    return 1 if different else 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--src", type=Path, required=True, help="source tree (a checkout or worktree)")
    r.add_argument("--out", type=Path, required=True)
    r.add_argument(
        "--set",
        dest="settings",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a setting for every run and baseline (repeatable)",
    )
    c = sub.add_parser("compare")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = ap.parse_args()
    if args.cmd == "run":
        run(args.src, args.out, args.settings)
    else:
        sys.exit(compare(args.a, args.b))


if __name__ == "__main__":
    main()
