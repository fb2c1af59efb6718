"""Before/after table of species dynamics for groups of run directories.

    python experiments/tools/speciation_table.py LABEL=RUN_DIR[,RUN_DIR...] [LABEL=...] [--last 50]
                                            [--founding-from 100] [--json OUT]

Each group is one setting of one scenario (e.g. `four-niche before=a,b,c`), its runs one seed
each. For every run, `swarmcode_torch.app.analysis.run_dynamics` gives the medians over the last
`--last` generations (species in the best team and in the population, niches, best-team score,
median species age) and the founding rate (all foundings, and those of species alive in two
generations or more: `founded_lasting_per_generation`) and median lifetime from generation
`--founding-from` to the end; the table shows each run's values and their mean ± std (sample
std over seeds) per group. Used in docs/RESULTS.md ("Speciation that settles").
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from swarmcode_torch.app.analysis import run_dynamics
from swarmcode_torch.app.runs import RunError, load_checkpoint
from swarmcode_torch.coevo.dynamics import mean_std as mean_std_of

#: (key, header, format of one run's value); mean and std take one more decimal
COLUMNS = (
    ("team_species", "team sp", "{:.1f}"),
    ("population_species", "pop sp", "{:.1f}"),
    ("niches", "niches", "{:.1f}"),
    ("team_score", "score", "{:.0f}"),
    ("founded_per_generation", "founded/gen", "{:.2f}"),
    ("founded_lasting_per_generation", "lasting/gen", "{:.2f}"),
    ("median_lifetime", "lifetime", "{:.1f}"),
    ("median_age", "age", "{:.0f}"),
)


def run_row(run: Path, last: int, founding_from: int) -> dict:
    end = int(load_checkpoint(run)["generation"])
    tail, long = run_dynamics(run, [(end - last, end), (founding_from, end)])
    return {
        **{
            k: tail[k]
            for k in ("team_species", "population_species", "niches", "team_score", "median_age")
        },
        "founded_per_generation": long["founded_per_generation"],
        "founded_lasting_per_generation": long["founded_lasting_per_generation"],
        "median_lifetime": long["median_lifetime"],
        "generations": end,
        "run": str(run),
    }


def mean_std(values: list[float], fmt: str) -> str:
    """Mean ± sample std of the values that are numbers (a window with no data gives NaN)."""
    values = [v for v in values if v is not None and not math.isnan(v)]
    if len(values) < 2:
        return fmt.format(values[0]) if values else "-"
    mean, std = mean_std_of(values)
    return f"{fmt.format(mean)} ± {fmt.format(std)}"


def cell(values: list[float], fmt: str) -> str:
    """'mean ± std (v1, v2, v3)'."""
    return (
        mean_std(values, fmt)
        + " ("
        + ", ".join("-" if v is None or math.isnan(v) else fmt.format(v) for v in values)
        + ")"
    )


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "groups",
        nargs="*",
        help="LABEL=RUN_DIR[,RUN_DIR...], or @FILE:LABEL[=SHOWN] "
        "(as --stored, in this place in the table)",
    )
    ap.add_argument("--last", type=int, default=50)
    ap.add_argument("--founding-from", type=int, default=100)
    ap.add_argument("--json", type=Path)
    ap.add_argument(
        "--stored",
        action="append",
        default=[],
        metavar="FILE:LABEL[=SHOWN]",
        help="a group's rows from an earlier --json output (runs whose checkpoints "
        "are not kept), shown as SHOWN",
    )
    a = ap.parse_args(argv)
    out = {}
    print("| group | runs | " + " | ".join(c[1] for c in COLUMNS) + " |")
    print("|---|---|" + "---|" * len(COLUMNS))
    groups = []
    for g in a.groups + ["@" + spec for spec in a.stored]:
        if g.startswith("@"):  # @FILE:LABEL[=SHOWN], as --stored, in its place
            path, _, labels = g[1:].partition(":")
            label, _, shown = labels.partition("=")
            try:
                groups.append((shown or label, json.loads(Path(path).read_text())[label]))
            except (OSError, ValueError, KeyError) as e:
                raise SystemExit(f"error: {g}: no group {label!r} in {path} ({e!r:.80})") from None
        else:
            groups.append((g, None))
    for g, stored in groups:
        if stored is not None:
            label, rows = g, stored
        else:
            label, _, dirs = g.partition("=")
            try:
                rows = [run_row(Path(d), a.last, a.founding_from) for d in dirs.split(",") if d]
            except RunError as e:
                raise SystemExit(f"error: {e}") from None
        out[label] = rows
        cells = [cell([r[k] for r in rows], fmt) for k, _, fmt in COLUMNS]
        print(f"| {label} | {len(rows)} | " + " | ".join(cells) + " |")
    if a.json:
        a.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
