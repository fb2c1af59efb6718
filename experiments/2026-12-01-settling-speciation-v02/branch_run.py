"""Branch a run at one of its snapshots with some settings changed, to compare an operator on
the same population: generations before the branch are the original run's, after it only the
changed settings (and the random streams they move) differ.

    python experiments/2026-12-01-settling-speciation-v02/branch_run.py SRC_RUN SNAPSHOT DST [--set KEY=VALUE ...] [--reseed S]
    swarmcode-torch evolve --resume DST --generations N

DST gets SRC_RUN's scenario.toml and hardware.toml, SNAPSHOT (a checkpoint file in SRC_RUN:
its checkpoint.pt, or a copy of it kept at an earlier generation, such as the snap_100.pt files
of the runs in experiments/2026-12-01-settling-speciation-v02/runs.tar.gz) as its checkpoint.pt, and the teams.jsonl
records of the generations before it; the settings are changed in config.toml
and in the checkpoint's saved config alike, so that `--resume` accepts the branch and the
branch records what it ran with. `--reseed S` replaces the run's random stream by a fresh one
seeded S: with no setting changed, a null branch, the same population continued by the same
algorithm with other random draws, which measures how far two continuations differ by chance.
Used in docs/RESULTS.md ("A lower effector rate", "How a niche is lost").
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import torch

from swarmcode_torch.app.runs import config_from_dict, read_checkpoint, write_config
from swarmcode_torch.app.settings import parse_settings


def branch(src: Path, snapshot: str, dst: Path, settings: dict,
           reseed: int | None = None) -> int:
    """Make the branch directory; returns the generation it starts from."""
    d = read_checkpoint(src / snapshot)
    if reseed is not None:
        d["rng_state"] = torch.Generator().manual_seed(reseed).get_state()
    cfg = config_from_dict({**d["config"], **settings}, f"{src / snapshot} (its config)")
    cfg.validate()
    dst.mkdir(parents=True)
    for f in ("scenario.toml", "hardware.toml"):
        if (src / f).is_file():
            shutil.copy2(src / f, dst / f)
    d["config"] = cfg.to_dict()
    torch.save(d, dst / "checkpoint.pt")
    write_config(dst, cfg)
    with open(src / "teams.jsonl") as fi, open(dst / "teams.jsonl", "w") as fo:
        for line in fi:
            try:
                keep = json.loads(line)["generation"] < d["generation"]
            except (ValueError, KeyError, TypeError):
                keep = False            # a line cut short by an interruption
            if keep:
                fo.write(line)
    return d["generation"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("src", type=Path)
    ap.add_argument("snapshot")
    ap.add_argument("dst", type=Path)
    ap.add_argument("--set", dest="settings", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--reseed", type=int, metavar="S",
                    help="continue with a fresh random stream seeded S (a null branch)")
    args = ap.parse_args()
    g = branch(args.src, args.snapshot, args.dst, parse_settings(args.settings), args.reseed)
    print(f"{args.dst}: branched from {args.src / args.snapshot} at generation {g}; continue "
          f"with: swarmcode-torch evolve --resume {args.dst} --generations N")


if __name__ == "__main__":
    main()
