"""What a run directory holds, worked out: species dynamics (species, niches, founding and
lifetimes over windows of generations; `swarmcode-torch dynamics RUN_DIR`), the capability of
each team design, and a replay of its best team as a GIF (`swarmcode-torch replay RUN_DIR`)."""

from __future__ import annotations

import io
from dataclasses import replace
from pathlib import Path
from typing import Sequence

from ..coevo.dynamics import median, niche_count, replay, window_stats
from ..coevo.population import genome_phenotype
from .render import record_episode, save_gif, team_genome
from .runs import (REPLAY_FILE, RunError, _size, atomic_write_bytes, estimate_bytes,
                   generation_team, load_checkpoint, memory_limit, read_config, read_summary,
                   read_teams, run_scenario)
from ..sim.scenario import Scenario
from ..sim.state import WorldParams, capabilities


def design_capabilities(designs: Sequence[dict], scenario: Scenario) -> list[list[int]]:
    """For each summary / teams.jsonl design, the indices of the scenario's package classes it
    can lift (the `capability` the run recorded, or computed from its genes for older runs)."""
    if all("capability" in d for d in designs):
        return [list(d["capability"]) for d in designs]
    genome, _ = team_genome(designs)
    can = capabilities(genome_phenotype(genome, scenario.hardware), scenario,
                       WorldParams.for_scenario(scenario))
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


def replay_run(run_dir: str | Path, out: str | Path | None = None, seed: int = 0,
               ticks: int | None = None, every: int = 2, generation: int | None = None,
               fps: float = 10, dpi: int = 80) -> tuple[Path, dict]:
    """Render the best team of a run (summary.json "designs"), or the best team of one
    `generation` (teams.jsonl), as a GIF.

    The run's config gives the episode length (``ticks`` overrides it) and its scenario.toml
    copy the scenario (the config's scenario in a run made before runs kept one); the
    environment is drawn from `seed`. RunError for an `out` whose folder does not exist, a run
    file that cannot be read or is malformed (its robots are built from the run's hardware.toml
    copy). Returns the GIF path (default ``run_dir/team.gif``) and
    the episode metrics as floats.
    """
    run_dir = Path(run_dir)
    out = Path(out) if out is not None else run_dir / REPLAY_FILE
    if out.is_dir():
        raise RunError(f"--out {out} is a directory; give a file name such as {out / REPLAY_FILE}")
    if not out.parent.is_dir():
        raise RunError(f"--out {out}: the folder {out.parent} does not exist")
    cfg = read_config(run_dir)
    if generation is not None:
        designs = generation_team(run_dir, generation)["designs"]
    else:
        designs = read_summary(run_dir, figures=False)["designs"]
    scenario = run_scenario(run_dir, cfg)        # the run's own copies, when it has them
    robots = sum(d["count"] for d in designs)
    need = estimate_bytes(replace(cfg, population=1, trials=1, swarm_size=robots), scenario)
    limit, what = memory_limit("cpu")
    if need > limit:
        raise RunError(f"the team to replay has {robots} robots, which would need about "
                       f"{_size(need)} of memory, more than the {_size(limit)} of {what}")
    genome, team = team_genome(designs, cfg.tag_length)
    if ticks is None:
        ticks = cfg.ticks or scenario.episode_ticks
    ep = record_episode(genome, team, scenario, seed, ticks=ticks, every=every)
    ep.labels = [f"sp{d.get('species', '?')} {lab}" for d, lab in zip(designs, ep.labels)]
    buf = io.BytesIO()
    save_gif(ep, buf, fps=fps, dpi=dpi)
    # replaced whole (a temporary file renamed over it): a link at `out` is replaced, never
    # written through, and a reader never sees half a GIF
    atomic_write_bytes(out, buf.getvalue())
    return out, dict(ep.metrics)
