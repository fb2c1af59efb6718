"""The compact, committed form of a run directory: what the study folders of experiments/ hold.

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
from swarmcode_torch.app.runs import (
    RunError,
    load_checkpoint,
    read_config,  # noqa: E402
    read_summary,
)


def compact(run: Path, out: Path, start: int = 0) -> list[dict]:
    """Write the compact form of `run` into `out`; return the rows of dynamics.json."""
    read_config(run)  # a run directory, checked, before anything is written
    read_summary(run)
    ck = load_checkpoint(run)
    out.mkdir(parents=True, exist_ok=True)
    for name in ("config.toml", "summary.json"):
        shutil.copy(run / name, out / name)
    end = int(ck["generation"])
    wins = [(lo, min(lo + 100, end)) for lo in range(start, end, 100)] + [(end - 50, end)]
    rows = [
        {"generations": hi - lo, "from": lo, "to": hi, **r}
        for (lo, hi), r in zip(wins, run_dynamics(run, wins))
    ]
    (out / "dynamics.json").write_text(json.dumps(rows, indent=1))
    fig = composition_figure(ck["history"])
    fig.savefig(out / "composition.png", dpi=60)
    plt.close(fig)
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--from", dest="start", type=int, default=0)
    a = ap.parse_args(argv)
    try:
        compact(a.run, a.out, a.start)
    except RunError as e:
        raise SystemExit(f"error: {e}") from None


if __name__ == "__main__":
    main()
