"""The two teams a replay compares: the focal team of a best-team record and its baseline
(the focal design's slots refilled by its partners), as rows of `episodes.team_genome`; used by
the page (`replay_page`) and the several-seed marginal (`replay_explain`)."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from .episodes import team_genome


def focal_and_baseline(designs: Sequence[dict], seed: int = 0) -> tuple[int, Tensor, Tensor, bool]:
    """(focal design index, focal team ``[S]``, baseline team ``[S]``, whether the baseline is
    the recorded one) as rows of ``team_genome(designs)`` (-1: an empty slot); see the module
    docstring of `replay_page`. A record that gives
    every design's ``baseline_count`` (runs made since the replay page) gives the baseline it was scored
    against: the partner slots as they are, the focal's slots refilled to those counts."""
    _, team = team_genome(designs)
    counts = [int(d.get("count", 1)) for d in designs]
    marked = [i for i, d in enumerate(designs) if d.get("focal") is True and counts[i] > 0]
    if marked:
        focal = marked[0]
    else:
        focal = max(range(len(designs)), key=lambda i: (counts[i], -i))
    partners = [i for i in range(len(designs)) if i != focal and counts[i] > 0]
    slots = team == focal
    n_slots = int(slots.sum())
    baseline = team.clone()
    recorded = _recorded_refill(designs, counts, focal, n_slots)
    if recorded is not None:
        baseline[slots] = recorded
    elif partners:
        w = torch.tensor([max(float(designs[i].get("dominance", 0.5)), 0.0) for i in partners])
        if float(w.sum()) <= 0:
            w = torch.ones(len(partners))
        g = torch.Generator().manual_seed(int(seed))
        draw = torch.multinomial(w, n_slots, replacement=True, generator=g)
        baseline[slots] = torch.tensor(partners)[draw]
    else:
        baseline[slots] = -1
    return focal, team, baseline, recorded is not None


def _recorded_refill(
    designs: Sequence[dict], counts: list[int], focal: int, n_slots: int
) -> Tensor | None:
    """The focal's slots as the record's baseline counts fill them ([n_slots] design rows, -1
    empty), or None where the record has none or they do not fit the team."""
    base = [d.get("baseline_count") for d in designs]
    if not all(isinstance(b, int) and not isinstance(b, bool) for b in base):
        return None
    if base[focal] != 0:
        return None
    extra = [b - c if i != focal else 0 for i, (b, c) in enumerate(zip(base, counts))]
    if any(e < 0 for e in extra):
        return None
    fill = [i for i, e in enumerate(extra) for _ in range(e)]
    if not fill and sum(base) == 0:
        return torch.full((n_slots,), -1, dtype=torch.long)  # no partner: an empty team
    if len(fill) != n_slots:
        return None
    return torch.tensor(fill, dtype=torch.long)


def species_count(designs: Sequence[dict], team: Tensor) -> int:
    """The distinct species among a team's designs (rows -1: empty slots)."""
    rows = sorted(set(team[team >= 0].tolist()))
    return len({designs[r].get("species", r) for r in rows})
