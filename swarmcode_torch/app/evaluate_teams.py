"""The teams `evaluate` scores: which records of a run (`choose_teams`), whether a scenario can
carry them, and how a design's slots are refilled when it is knocked out (`evaluate`'s
docstring says the rules)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from ..coevo.population import from_designs, genome_phenotype
from ..sim.scenario import Scenario
from .files import RunError
from .summary import check_designs, read_summary, read_teams
from .team_eval import TEAM_GENES


# ------------------------------------------------------------------ the teams of a run
@dataclass(frozen=True)
class _Chosen:
    source: str
    generation: int | None
    recorded_fitness: float | None
    designs: list[dict]


def _number(v: Any) -> float | None:
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    return float(v) if ok else None


def _int(v: Any) -> int | None:
    return v if isinstance(v, int) and not isinstance(v, bool) else None


def _team_key(designs: list[dict]) -> str:
    """Two records of the same team have the same key: each design's genes and robots."""
    import json

    return json.dumps(sorted(json.dumps([d[k] for k in TEAM_GENES]) for d in designs))


def choose_teams(
    run_dir: Path, team: str = "best", generation: int | None = None, top: int | None = None
) -> list[_Chosen]:
    """The team(s) to evaluate (see the module docstring); RunError where the run has none."""
    if generation is not None or team == "last":
        records = read_teams(run_dir)
        if not records:
            raise RunError(f"{run_dir} has no teams.jsonl records (no finished generation?)")
        g = max(records) if generation is None else generation
        if g not in records:
            raise RunError(
                f"{run_dir} has no record of generation {g} (its teams.jsonl holds "
                f"generations {min(records)}..{max(records)})"
            )
        rec = records[g]
        check_designs(rec.get("designs"), f"{run_dir / 'teams.jsonl'} (generation {g})")
        return [
            _Chosen(
                "generation" if generation is not None else "last",
                g,
                _number(rec.get("fitness")),
                rec["designs"],
            )
        ]
    if top is not None:
        found: dict[str, _Chosen] = {}
        records = read_teams(run_dir)
        for g in sorted(records):
            rec = records[g]
            fit = _number(rec.get("fitness"))
            if fit is None:
                continue
            try:
                designs = check_designs(rec.get("designs"), "teams.jsonl")
            except RunError:
                continue  # a damaged record is not among the best
            key = _team_key(designs)
            if key not in found or fit > (found[key].recorded_fitness or -math.inf):
                found[key] = _Chosen("top", g, fit, designs)
        if not found:
            raise RunError(f"{run_dir} has no teams.jsonl record with a fitness and designs")
        ranked = sorted(found.values(), key=lambda c: (-(c.recorded_fitness or 0.0), c.generation))
        return ranked[:top]
    s = read_summary(run_dir, figures=False)
    return [
        _Chosen(
            "best", _int(s.get("best_generation")), _number(s.get("best_fitness")), s["designs"]
        )
    ]


# ------------------------------------------------------------------ knock-outs
def _refill(
    designs: list[dict],
    d: int,
    team: Tensor,
    seeds: Sequence[int],
    near: Tensor | None,
    uniform: bool,
    recorded: Tensor | None,
) -> tuple[Tensor, str]:
    """[N, S] the team (rows of its own designs) with design `d` knocked out in each episode,
    and how its slots were refilled (module docstring)."""
    n_ep = len(seeds)
    slots = team == d
    n_slots = int(slots.sum())
    out = team.repeat(n_ep, 1)
    partners = [i for i, x in enumerate(designs) if i != d and int(x["count"]) > 0]
    if recorded is not None:
        out[:, slots] = recorded
        return out, "recorded baseline"
    if not partners:
        out[:, slots] = -1
        return out, "no partner"
    if near is not None:
        order = sorted(partners, key=lambda i: (float(near[d, i]), designs[i]["species"], i))
        out[:, slots] = order[0]
        return out, "nearest partner"
    w = torch.tensor([max(float(designs[i]["dominance"]), 0.0) for i in partners])
    if uniform or float(w.sum()) <= 0:
        w = torch.ones(len(partners))
    rows = torch.tensor(partners)
    for e, seed in enumerate(seeds):
        g = torch.Generator().manual_seed(int(seed))
        out[e, slots] = rows[torch.multinomial(w, n_slots, replacement=True, generator=g)]
    return out, "dominance draw"


def _recorded_baseline(designs: list[dict], team: Tensor) -> tuple[int | None, Tensor | None]:
    """(the focal design, the refill of its slots) where the record gives the baseline it was
    scored against (`replay_page.focal_and_baseline`); otherwise (the design the record marks
    as the focal, or None; None)."""
    from .replay_page import focal_and_baseline

    marked = [i for i, x in enumerate(designs) if x.get("focal") is True and int(x["count"]) > 0]
    focal, _, base, recorded = focal_and_baseline(designs, 0)
    if not recorded:
        return (marked[0] if marked else None), None
    return focal, base[team == focal]


def _check_team_fits(designs: list[dict], scenario: Scenario, own: bool) -> None:
    robots = sum(int(d["count"]) for d in designs)
    if not own and robots > scenario.num_robots:
        raise RunError(
            f"scenario {scenario.name} is a world for {scenario.num_robots} robots and cannot "
            f"carry the team's {robots}; give a scenario of at least {robots} robots"
        )
    genome, _ = from_designs(designs)
    ph = genome_phenotype(genome, scenario.hardware)
    good = torch.stack([torch.isfinite(t.float()).all() for t in ph]).all()
    good &= (ph.mass > 0).all() & (ph.capacity > 0).all()
    if not bool(good):
        raise RunError(
            f"the hardware catalog of scenario {scenario.name} cannot build the team's designs "
            "(a robot of non-finite or non-positive mass or battery)"
        )
