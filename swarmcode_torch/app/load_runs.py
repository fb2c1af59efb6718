"""Many runs as one table: `load_runs("runs/*")`, one row per run directory, its settings
(every key of its config.toml) and its summary's measures as columns.

    import swarmcode_torch as sc

    runs = sc.load_runs("runs/sweep-*/*")            # a list of dicts, one per run
    df = runs.to_pandas()                            # a DataFrame (needs pandas)
    df.groupby(["delta", "population"]).best_fitness.mean()

pandas is an optional extra (`pip install -e ".[pandas]"`), so `load_runs` returns a list of
dicts (`Runs`) and `Runs.to_pandas()` makes the DataFrame, as `RunResult.to_pandas()` does.
"""

from __future__ import annotations

import glob
import os
from pathlib import Path
from typing import Any

from .files import CONFIG_FILE, SUMMARY_FILE, RunError
from .runconfig import read_config

#: The measures of a run's summary.json each row has (None where the run has none yet).
MEASURES = (
    "best_fitness",
    "best_generation",
    "team_cost",
    "num_species",
    "niches",
    "deliveries",
    "deliveries_individual",
    "deliveries_collab",
    "energy_used",
    "species_in_population",
)


class Runs(list):
    """The rows `load_runs` returns: a list of dicts, each "run" (its directory), every
    setting of its config, "generations_done", the `MEASURES` and "stopped" (why it stopped
    before its last generation, None when it did not)."""

    def to_pandas(self):
        """The rows as a pandas DataFrame, one row per run, one column per key."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError(
                "Runs.to_pandas() needs pandas: pip install pandas (or pip install -e "
                "'.[pandas]' in the source tree); the Runs themselves are a list of dicts"
            ) from None
        return pd.DataFrame(list(self))


def run_row(run_dir: Path) -> dict[str, Any]:
    """One run's row (`Runs`). RunError for a config or summary.json that cannot be read."""
    from .summary import read_summary

    cfg = read_config(run_dir)
    row: dict[str, Any] = {"run": str(run_dir), **cfg.to_dict()}
    summary = read_summary(run_dir) if (run_dir / SUMMARY_FILE).exists() else {}
    g = summary.get("generation")
    row["generations_done"] = g + 1 if isinstance(g, int) else 0
    for key in MEASURES:
        row[key] = summary.get(key)
    stop = summary.get("stop")
    reason = stop.get("reason") if isinstance(stop, dict) else None
    row["stopped"] = None if reason in (None, "generations") else reason
    return row


def _run_dirs(path: Path) -> list[Path]:
    """`path` if it is a run directory, its runs if it is a sweep directory, else none."""
    if (path / CONFIG_FILE).is_file():
        return [path]
    if not path.is_dir():
        return []
    return sorted(p for p in path.iterdir() if p.is_dir() and (p / CONFIG_FILE).is_file())


def load_runs(*patterns: str | os.PathLike) -> Runs:
    """The runs that glob patterns match, one row each, in the order of their paths.

    Args:
        *patterns: globs such as "runs/*" or "runs/sweep-*/*"; a sweep directory stands for its
            runs; a path matched twice is one row.

    Returns:
        The `Runs` (`to_pandas()`: one DataFrame with the settings as columns).

    Raises:
        RunError: naming a run whose config or summary.json cannot be read.
        ValueError: no pattern given.
    """
    if not patterns:
        raise ValueError('load_runs needs a pattern, e.g. load_runs("runs/*")')
    seen: dict[str, Path] = {}
    for pattern in patterns:
        if not isinstance(pattern, (str, os.PathLike)):
            raise TypeError(f"a pattern must be a path or a string, got {type(pattern).__name__}")
        for match in sorted(glob.glob(os.fspath(pattern))):
            for d in _run_dirs(Path(match)):
                seen.setdefault(os.path.normpath(d), d)
    rows = Runs()
    for key in sorted(seen):
        try:
            rows.append(run_row(seen[key]))
        except RunError:
            raise
        except (OSError, ValueError) as e:
            raise RunError(f"{seen[key]} cannot be read: {e}") from None
    return rows
