"""The run's best team as the command line prints it: its figures, how its fitness was measured
and a table of its designs (`print_team`)."""

from __future__ import annotations

from pathlib import Path

from rich import box
from rich.table import Table

from .cli_output import console, fail


def _num(v, fmt: str) -> str:
    return "n/a" if v is None else format(v, fmt)


def best_interval(s: dict) -> str:
    """How summary.json's best fitness was measured, for the line after it: " (mean of K fresh
    environments, 95 % interval LO to HI; the highest single evaluation of the run: F in
    generation G)"; "" for a run whose best team was not re-evaluated."""
    k, ci = s.get("best_reeval_trials"), s.get("best_fitness_ci95")
    if not k:
        return ""
    interval = f", 95 % interval {ci[0]:.2f} to {ci[1]:.2f}" if ci else ""
    single = s.get("best_single_trial_fitness")
    highest = (
        f"; the highest single evaluation of the run: {single:.2f} in generation "
        f"{s.get('best_single_trial_generation')}"
        if single is not None
        else ""
    )
    return f" (mean of {k} fresh environments{interval}{highest})"


def print_team(run_dir: Path) -> None:
    from .runs import RunError, read_summary

    try:
        s = read_summary(run_dir)
    except RunError as e:
        fail(str(e))
    designs = s["designs"]
    budget = "none" if s.get("budget") is None else f"${s['budget']:g}"
    console.print(
        f"Best team (generation {s['best_generation']}): fitness {_num(s['best_fitness'], '.2f')}"
        f"{best_interval(s)}, cost ${_num(s['team_cost'], '.0f')} (budget {budget}), {s['num_species']} species, "
        f"deliveries {_num(s['deliveries'], '.2f')} ({_num(s['deliveries_individual'], '.2f')} "
        f"individual, {_num(s['deliveries_collab'], '.2f')} collaborative), energy used "
        f"{_num(s['energy_used'], '.1f')}%",
        markup=False,
    )
    t = Table(
        title="Robots per design",
        box=box.SIMPLE_HEAD,
        caption="ch/bat/mot: chassis, battery, motor tier (1-3); torque, capacity: "
        "operating points (0-1); dom: dominance",
    )
    for col in (
        "robots",
        "species",
        "tool",
        "radius",
        "ch",
        "bat",
        "mot",
        "torque",
        "capacity",
        "dom",
        "$ each",
    ):
        t.add_column(col, justify="right", no_wrap=True)
    for d in designs:
        t.add_row(
            str(d["count"]),
            str(d["species"]),
            d["effector"],
            f"{d['radius']:.3f}",
            str(d["chassis_tier"]),
            str(d["battery_tier"]),
            str(d["motor_tier"]),
            f"{d['torque_point']:.2f}",
            f"{d['battery_point']:.2f}",
            f"{d['dominance']:.2f}",
            f"{d['cost']:.0f}",
        )
    console.print(t)
    return designs
