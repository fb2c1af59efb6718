"""The compact, committed form of a run directory: what experiments/2026-12-02-one-partner-per-niche-v04/ and v05/ hold.

    python experiments/tools/compact_run.py RUN OUT [--from 0]

OUT gets the run's config.toml and summary.json, dynamics.json (`app.analysis.run_dynamics`
over windows of 100 generations from --from, and the last 50) and composition.png (the
species sizes per generation, `app.reporting.composition_figure`).
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from swarmcode_torch.app.analysis import run_dynamics  # noqa: E402
from swarmcode_torch.app.reporting import composition_figure  # noqa: E402
from swarmcode_torch.app.runs import load_checkpoint  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--from", dest="start", type=int, default=0)
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    for name in ("config.toml", "summary.json"):
        shutil.copy(a.run / name, a.out / name)
    ck = load_checkpoint(a.run)
    end = int(ck["generation"])
    wins = [(lo, min(lo + 100, end)) for lo in range(a.start, end, 100)] + [(end - 50, end)]
    rows = run_dynamics(a.run, wins)
    (a.out / "dynamics.json").write_text(json.dumps(
        [{"generations": hi - lo, "from": lo, "to": hi, **r} for (lo, hi), r in zip(wins, rows)],
        indent=1))
    fig = composition_figure(ck["history"])
    fig.savefig(a.out / "composition.png", dpi=60)
    plt.close(fig)


if __name__ == "__main__":
    main()
