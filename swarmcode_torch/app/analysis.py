"""Species dynamics of a run directory: species, niches, founding and lifetimes over windows of
generations (`swarmcode-torch dynamics RUN_DIR`), and the capability of each team design."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from ..coevo.dynamics import median, niche_count, replay, window_stats
from ..coevo.population import genome_phenotype
from .runs import RunError, load_checkpoint, read_config, read_teams, run_scenario
from ..sim.scenario import Scenario
from ..sim.state import WorldParams, capabilities


def design_capabilities(designs: Sequence[dict], scenario: Scenario) -> list[list[int]]:
    """For each summary / teams.jsonl design, the indices of the scenario's package classes it
    can lift (the `capability` the run recorded, or computed from its genes for older runs)."""
    from .render import team_genome

    if all("capability" in d for d in designs):
        return [list(d["capability"]) for d in designs]
    genome, _ = team_genome(designs)
    can = capabilities(genome_phenotype(genome), scenario, WorldParams.for_scenario(scenario))
    return [[j for j, ok in enumerate(row) if ok] for row in can.tolist()]


def team_records(run_dir: Path, scenario: Scenario) -> dict[int, dict]:
    """generation -> {"niches", "score"} of its best team, from teams.jsonl (`runs.read_teams`;
    a record without the fields it needs is skipped)."""
    out: dict[int, dict] = {}
    for g, rec in read_teams(run_dir).items():
        try:
            niches = int(rec["niches"]) if "niches" in rec else \
                niche_count(design_capabilities(rec["designs"], scenario))
            out[g] = {"niches": niches, "score": float(rec["fitness"])}
        except (KeyError, TypeError, ValueError):
            continue
    return out


def default_windows(last_generation: int, step: int = 100, tail: int = 50) -> list[tuple[int, int]]:
    """[0, step), [step, 2 step), ... up to the end, then the last `tail` generations."""
    end = last_generation + 1
    wins = [(a, min(a + step, end)) for a in range(0, end, step)]
    if end > tail and (end - tail, end) not in wins:
        wins.append((end - tail, end))
    return wins


def run_dynamics(run_dir: Path, windows: Sequence[tuple[int, int]] | None = None) -> list[dict]:
    """`dynamics.window_stats` of each window of a run directory (default `default_windows`)."""
    run_dir = Path(run_dir)
    cfg = read_config(run_dir)
    history = load_checkpoint(run_dir)["history"]
    if not history:
        raise RunError(f"{run_dir} has no finished generation")
    try:
        scenario = run_scenario(run_dir, cfg)      # the run's own copy where it kept one
    except ValueError as e:
        raise RunError(f"{run_dir}: its scenario cannot be loaded ({e})") from None
    turnover, rows = replay(history)
    teams = team_records(run_dir, scenario)
    niches = {g: t["niches"] for g, t in teams.items()}
    last = rows[-1]["generation"]
    out = []
    for a, b in windows or default_windows(last):
        st = window_stats(rows, turnover, a, b, niches)
        st["team_score"] = median([t["score"] for g, t in teams.items() if a <= g < b])
        out.append(st)
    return out
