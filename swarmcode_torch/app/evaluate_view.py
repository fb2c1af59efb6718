"""`swarmcode-torch evaluate RUN_DIR`: its options checked, the evaluation run (`evaluate`) with
a progress bar on a terminal, the results as tables, and `--json FILE` written atomically."""

from __future__ import annotations

import json
from pathlib import Path

from rich import box
from rich.markup import escape
from rich.table import Table

from ..coevo.config import MAX_SEED, UPPER_BOUNDS
from ..sim.scenario import ScenarioError
from .evaluate import MAX_EPISODES, MAX_TOP, EvaluationResult, Stat, TeamEvaluation, evaluate
from .files import RunError, atomic_write_bytes, check_output_path
from .records import json_clean
from .replay_view import stage_progress
from .terminal import check_path, console, fail, os_fail


def _interval(s: Stat, fmt: str = "{:.3f}") -> str:
    if s.low is None or s.high is None:
        return "-"
    return f"[{fmt.format(s.low)}, {fmt.format(s.high)}]"


def _sd(s: Stat, fmt: str = "{:.3f}") -> str:
    return "-" if s.sd is None else fmt.format(s.sd)


def _team_title(t: TeamEvaluation, i: int, n: int) -> str:
    where = {
        "best": "the best team",
        "last": "the last generation's team",
        "generation": "the best team",
        "top": f"team {i + 1} of the top {n}",
    }[t.source]
    gen = f" (generation {t.generation})" if t.generation is not None else ""
    rec = f", recorded fitness {t.recorded_fitness:.3f}" if t.recorded_fitness is not None else ""
    return f"{where}{gen}: {t.robots} robots, {t.species} species, cost ${t.cost:.0f}{rec}"


def print_result(r: EvaluationResult) -> None:
    """The evaluation as tables: per team its fitness and deliveries, then its designs'
    knock-out contributions."""
    scen = f"scenario {r.scenario}" + ("" if r.own_scenario else " (not the run's)")
    console.print(
        f"[bold]{escape(r.run_dir)}[/]: {r.episodes} episodes, seeds {r.seeds[0]}..{r.seeds[1]}, "
        f"{escape(scen)}, {r.ticks} ticks, {r.device} ({r.tick} tick), "
        f"fitness {escape(r.fitness_function)}",
        highlight=False,
        soft_wrap=True,
    )
    for i, t in enumerate(r.teams):
        table = Table(
            title=_team_title(t, i, len(r.teams)),
            box=box.SIMPLE_HEAD,
            caption="sd: of the episodes; interval: 95 % t interval of the mean",
        )
        for col in ("", "mean", "sd", "95 % interval"):
            table.add_column(col, justify="left" if not col else "right", no_wrap=True)
        table.add_row("fitness", f"{t.fitness.mean:.3f}", _sd(t.fitness), _interval(t.fitness))
        table.add_row(
            "deliveries",
            f"{t.deliveries_total.mean:.2f}",
            _sd(t.deliveries_total, "{:.2f}"),
            _interval(t.deliveries_total, "{:.2f}"),
        )
        for d in t.deliveries:
            table.add_row(
                escape(f"  {d['label']} (of {d['packages']})"), f"{d['mean']:.2f}", "", ""
            )
        console.print(table)
        kt = Table(
            title="knock-outs: the team's fitness less the team's without the design",
            box=box.SIMPLE_HEAD,
            caption="its slots refilled from the other designs as the run built baselines",
        )
        for col in ("design", "species", "robots", "effector", "refill", "without it"):
            kt.add_column(col, no_wrap=True)
        for col in ("contribution", "95 % interval"):
            kt.add_column(col, justify="right", no_wrap=True)
        for c in t.contributions:
            kt.add_row(
                f"{c.design}{' (focal)' if c.focal else ''}",
                str(c.species),
                str(c.robots),
                c.effector,
                c.refill,
                f"{c.knockout_fitness.mean:.3f}",
                f"{c.contribution.mean:+.3f}",
                _interval(c.contribution, "{:+.3f}"),
            )
        console.print(kt)


def _check_options(
    team_name: str | None,
    generation: int | None,
    top: int | None,
    episodes: int,
    seed_start: int,
    ticks: int | None,
    threads: int | None,
) -> None:
    """evaluate's options checked: one of --team, --generation and --top, each in its range;
    a one-line error and exit otherwise (`fail`)."""
    given = [
        name
        for name, v in (("--team", team_name), ("--generation", generation), ("--top", top))
        if v is not None
    ]
    if len(given) > 1:
        fail(f"{' and '.join(given)}: give one of --team, --generation and --top")
    if not 1 <= episodes <= MAX_EPISODES:
        fail(f"--episodes must be in [1, {MAX_EPISODES}], got {episodes}")
    if not 0 <= seed_start <= MAX_SEED - episodes + 1:
        fail(
            f"--seed-start must be in [0, {MAX_SEED - episodes + 1}] (the last seed, "
            f"S + N - 1, at most 2**63 - 1), got {seed_start}"
        )
    if generation is not None and generation < 0:
        fail(f"--generation must be >= 0, got {generation}")
    if top is not None and not 1 <= top <= MAX_TOP:
        fail(f"--top must be in [1, {MAX_TOP}], got {top}")
    if ticks is not None and not 1 <= ticks <= UPPER_BOUNDS["ticks"]:
        fail(f"--ticks must be in [1, {UPPER_BOUNDS['ticks']}], got {ticks}")
    if threads is not None and threads < 1:
        fail(f"--threads must be >= 1, got {threads}")


def evaluate_command(
    run_dir: str,
    team,
    generation: int | None,
    top: int | None,
    episodes: int,
    seed_start: int,
    scenario: str | None,
    ticks: int | None,
    json_out: str | None,
    device: str,
    threads: int | None,
) -> None:
    path = check_path(run_dir, "RUN_DIR")
    out = check_path(json_out, "--json")
    team_name = None if team is None else getattr(team, "value", team)
    _check_options(team_name, generation, top, episodes, seed_start, ticks, threads)
    assert path is not None
    if not path.is_dir():
        fail(f"{path} is not a directory")
    try:
        if out is not None:
            check_output_path(out, "--json")
        with stage_progress() as progress:
            result = evaluate(
                path,
                team=team_name or "best",
                generation=generation,
                top=top,
                episodes=episodes,
                seed_start=seed_start,
                scenario=scenario,
                device=device,
                ticks=ticks,
                threads=threads,
                progress=progress,
            )
        if out is not None:
            check_output_path(out, "--json")  # again: it may have changed while it ran
            data = json.dumps(json_clean(result.to_dict()), indent=2, allow_nan=False)
            atomic_write_bytes(Path(out), (data + "\n").encode())
    except (RunError, ScenarioError, ValueError, TypeError) as e:
        fail(str(e))
    except OSError as e:
        os_fail(e, "evaluate failed")
    print_result(result)
    if out is not None:
        console.print(f"Wrote {out}", markup=False, highlight=False, soft_wrap=True)
