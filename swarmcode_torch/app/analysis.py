"""What a run directory holds, worked out: species dynamics (species, niches, founding and
lifetimes over windows of generations; `swarmcode-torch dynamics RUN_DIR`), the capability of
each team design, and a replay of its best team as a GIF (`swarmcode-torch replay RUN_DIR`)."""

from __future__ import annotations

import io
import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

from ..coevo.config import MAX_SEED
from ..coevo.dynamics import median, niche_count, replay, window_stats
from ..sim.scenario import Scenario
from .checkpoints import load_checkpoint
from .episodes import Episode, ProgressFn
from .files import (
    REPLAY_FILE,
    SUMMARY_FILE,
    TEAMS_FILE,
    RunError,
    atomic_write_bytes,
    check_output_path,
)
from .frames import save_gif
from .records import design_capabilities
from .render import record_episode, team_genome
from .replay_explain import MAX_REPLAY_SEEDS, explain_lines, seed_marginals
from .replay_page import HTML_FILE, page_data, write_page
from .runconfig import _size, estimate_bytes, memory_limit, read_config, run_scenario
from .summary import check_capability_classes, generation_team, read_summary, read_teams


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


#: Bounds of a replay's options, the same for `replay` and `replay_run` (a GIF or a page of a
#: million ticks never finished; dpi 10^6 asked for terabytes).
MAX_REPLAY_TICKS = 20_000
REPLAY_FPS = (0.1, 100.0)
REPLAY_DPI = (10, 600)


def _integer(name: str, v, lo: int, hi: int) -> None:
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise RunError(f"{name} must be an integer in [{lo}, {hi}], got {v!r:.60}")


def check_replay_options(seed=0, ticks=None, every=2, fps: float = 10, dpi: int = 80) -> None:
    """RunError, naming the option and its bounds, for a replay option out of bounds."""
    _integer("seed", seed, 0, MAX_SEED)
    if ticks is not None:
        _integer("ticks", ticks, 1, MAX_REPLAY_TICKS)
    _integer("every", every, 1, MAX_REPLAY_TICKS)
    if (
        isinstance(fps, bool)
        or not isinstance(fps, (int, float))
        or not (REPLAY_FPS[0] <= fps <= REPLAY_FPS[1])
    ):
        raise RunError(
            f"fps must be a number in [{REPLAY_FPS[0]:g}, {REPLAY_FPS[1]:g}], got {fps!r:.60}"
        )
    _integer("dpi", dpi, *REPLAY_DPI)


def _by_design(ep: Episode, designs: Sequence[dict]) -> str:
    """One line: each design's deliveries and pick-ups in the episode (`Episode.credits`)."""
    counts = ep.credit_counts()
    prog = ep.robots.program[0]
    parts = []
    for d, rec in enumerate(designs):
        mine = counts[(prog == d) & ep.robots.present[0]]
        if mine.shape[0]:
            parts.append(
                f"species {rec.get('species', '?')} ({mine.shape[0]} robots): "
                f"{int(mine[:, :2].sum())} delivered, {int(mine[:, 2:].sum())} picked up"
            )
    return "By design: " + "; ".join(parts)


def team_records(run_dir: Path, scenario: Scenario) -> dict[int, dict]:
    """generation -> {"niches", "score"} of its best team, from teams.jsonl (`summary.read_teams`;
    a record without the fields it needs is skipped)."""
    out: dict[int, dict] = {}
    for g, rec in read_teams(run_dir).items():
        try:
            niches = (
                int(rec["niches"])
                if "niches" in rec
                else niche_count(design_capabilities(rec["designs"], scenario))
            )
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
    """The species dynamics of a run in windows of generations (`dynamics.window_stats`).

    Args:
        run_dir: the run directory.
        windows: (START, END) generation pairs, START < END (a START before 0 counts from
            generation 0); default: `default_windows`.

    Returns:
        One dict of statistics per window.

    Raises:
        RunError: a window that is not two integers START < END.
    """
    for w in windows or ():
        if (
            not isinstance(w, (tuple, list))
            or len(w) != 2
            or any(isinstance(x, bool) or not isinstance(x, int) for x in w)
            or not w[0] < w[1]
        ):
            raise RunError(f"windows: each window must be two integers START < END, got {w!r:.60}")
    run_dir = Path(run_dir)
    cfg = read_config(run_dir)
    history = load_checkpoint(run_dir)["history"]
    if not history:
        raise RunError(f"{run_dir} has no finished generation")
    try:
        scenario = run_scenario(run_dir, cfg)  # the run's own copy where it kept one
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


# long: its docstring is the public API's parameter table (the docs' reference); the code is under 80 lines
def replay_run(
    run_dir: str | Path,
    out: str | Path | None = None,
    seed: int = 0,
    ticks: int | None = None,
    every: int = 2,
    generation: int | None = None,
    fps: float = 10,
    dpi: int = 80,
    html: bool = False,
    progress: ProgressFn | None = None,
    report: Callable[[str], None] | None = None,
    seeds: int = 1,
) -> tuple[Path, dict]:
    """Render the best team of a run as a GIF, or as an interactive page.

    The run's config gives the episode length and its scenario.toml copy the scenario (the
    config's scenario in a run made before runs kept one); its robots are built from the run's
    hardware.toml copy. The episodes run on the CPU's tick (`sim.runtime.tick_function`, as
    evolution's).

    Args:
        run_dir: the run directory.
        out: the file to write (default ``run_dir/team.gif``, with `html` ``run_dir/team.html``).
        seed: the seed the environment is drawn from.
        ticks: the episode length (default: the run's).
        every: draw every k-th tick (GIF).
        generation: replay this generation's best team (teams.jsonl) instead of the run's
            (summary.json "designs").
        fps: frames per second of the GIF.
        dpi: the GIF's resolution.
        html: write one self-contained HTML page instead (`replay_page`): the team and its
            baseline team (the focal design's slots refilled by its partners) side by side in the
            same environment, every tick, with each robot's design, energy, load and behavior
            tree; `every`, `fps` and `dpi` do not apply.
        progress: `progress(stage, done, total)`, told of the ticks recorded and the frames drawn.
        report: `report(line)` gets lines that explain the replay: deliveries and pick-ups by
            design and, for the page, the tick at which the two arenas part.
        seeds: more than 1: the focal's marginal contribution over that many environments
            (seeds `seed`, `seed` + 1, ...), its mean on the page and in a reported line
            (`replay_seeds`).

    Returns:
        The path written and the episode metrics as floats (the focal team's, for a page).

    Raises:
        RunError: an `out` whose folder does not exist, a run file that cannot be read or is
            malformed.
    """
    check_replay_options(seed=seed, ticks=ticks, every=every, fps=fps, dpi=dpi)
    _integer("seeds", seeds, 1, min(MAX_REPLAY_SEEDS, MAX_SEED - seed + 1))
    run_dir = Path(run_dir)
    out = _replay_path(run_dir, out, html)
    cfg = read_config(run_dir)
    record, scenario = _replay_team(run_dir, cfg, generation, seeds)
    if ticks is None:
        ticks = cfg.ticks or scenario.episode_ticks
    if html:
        what = f"generation {generation}" if generation is not None else "best team"
        data = page_data(
            record["designs"],
            scenario,
            cfg,
            seed=seed,
            ticks=ticks,
            title=f"SwarmCoDe replay: {run_dir.name}, {what}",
            record=_page_record(run_dir, record, generation),
            progress=progress,
            seeds=seeds,
        )
        write_page(data, out)
        if report is not None:
            for line in explain_lines(data):
                report(line)
        return out, dict(data["panels"]["focal"]["metrics"])
    ep, gif = _replay_gif(record["designs"], scenario, cfg, seed, ticks, every, fps, dpi, progress)
    if report is not None:
        _report_gif(report, ep, record["designs"], scenario, cfg, seed, seeds, ticks)
    # replaced whole (a temporary file renamed over it): a link at `out` is replaced, never
    # written through, and a reader never sees half a GIF
    atomic_write_bytes(out, gif)
    return out, dict(ep.metrics)


def _replay_path(run_dir: Path, out: str | Path | None, html: bool) -> Path:
    """Where a replay is written: `out`, or the run's team.gif (team.html for `html`); RunError
    for a folder or an output path that cannot be written."""
    default = run_dir / (HTML_FILE if html else REPLAY_FILE)
    path = Path(out) if out is not None else default
    if path.is_dir() and not path.is_symlink():
        raise RunError(
            f"--out {path} is a directory; give a file name such as {path / default.name}"
        )
    check_output_path(path)
    return path


def _replay_team(run_dir: Path, cfg, generation: int | None, seeds: int) -> tuple[dict, Scenario]:
    """The record of the team to replay (summary.json's, or teams.jsonl's of `generation`) and
    the run's scenario (its own copies, when it has them); RunError for a design with
    capabilities of classes the scenario lacks, or a team whose `seeds` episodes would not fit
    in memory."""
    if generation is not None:
        record = generation_team(run_dir, generation)
    else:
        record = read_summary(run_dir, figures=False)
    designs = record["designs"]
    scenario = run_scenario(run_dir, cfg)  # the run's own copies, when it has them
    source = (
        f"{run_dir / TEAMS_FILE} (generation {generation})"
        if generation is not None
        else str(run_dir / SUMMARY_FILE)
    )
    check_capability_classes(designs, len(scenario.packages), source)
    robots = sum(d["count"] for d in designs)
    need = estimate_bytes(replace(cfg, population=1, trials=seeds, swarm_size=robots), scenario)
    limit, what = memory_limit("cpu")
    if need > limit:
        raise RunError(
            f"the team to replay has {robots} robots, which would need about "
            f"{_size(need)} of memory, more than the {_size(limit)} of {what}"
        )
    return record, scenario


def _page_record(run_dir: Path, record: dict, generation: int | None) -> dict:
    """What the replay page shows of the team's record: the run, its fitness (the re-evaluated
    mean and its interval where the run has them, `best_team`), its generation; numbers only
    (the page escapes text as well), those the record lacks left out."""
    fitness = record.get("fitness") if generation is not None else record.get("best_fitness")
    shown = generation if generation is not None else record.get("best_generation")
    # the re-evaluated mean and its interval where the run has them (`best_team`)
    reeval = record.get("reeval") if generation is not None else None
    if isinstance(reeval, dict):
        fitness, k, ci = reeval.get("mean"), reeval.get("trials"), reeval.get("ci95")
    elif generation is None:
        k, ci = record.get("best_reeval_trials"), record.get("best_fitness_ci95")
    else:
        k = ci = None
    if not (isinstance(ci, list) and len(ci) == 2):
        ci = [None, None]
    # only numbers reach the page from the run's records (the page escapes text as well)
    rec = {
        "run": run_dir.name,
        "fitness": float(fitness) if _finite(fitness) else None,
        "generation": shown if isinstance(shown, int) and not isinstance(shown, bool) else None,
        "trials": k if isinstance(k, int) and not isinstance(k, bool) and k > 0 else None,
        "fitness_low": float(ci[0]) if _finite(ci[0]) else None,
        "fitness_high": float(ci[1]) if _finite(ci[1]) else None,
    }
    return {k: v for k, v in rec.items() if v is not None}


def _replay_gif(
    designs, scenario, cfg, seed, ticks, every, fps, dpi, progress
) -> tuple[Episode, bytes]:
    """The team's episode recorded, and its GIF's bytes."""
    genome, team = team_genome(designs, cfg.tag_length)
    ep = record_episode(genome, team, scenario, seed, ticks=ticks, every=every, progress=progress)
    ep.labels = [f"sp{d.get('species', '?')} {lab}" for d, lab in zip(designs, ep.labels)]
    buf = io.BytesIO()
    save_gif(ep, buf, fps=fps, dpi=dpi, progress=progress)
    return ep, buf.getvalue()


def _report_gif(report, ep: Episode, designs, scenario, cfg, seed, seeds, ticks) -> None:
    """The lines that explain a GIF replay: deliveries and pick-ups by design, and with `seeds`
    > 1 the marginal contribution over that many environments."""
    report(_by_design(ep, designs))
    if seeds > 1:
        sm = seed_marginals(designs, scenario, cfg, seed, seeds, ticks)
        sd = f", sd {sm['sd']:.1f}" if sm["sd"] is not None else ""
        report(
            f"Marginal contribution over {seeds} environments (seeds {seed}-"
            f"{seed + seeds - 1}): mean {sm['mean']:.1f}{sd}"
        )
