"""Species dynamics: foundings, extinctions, ages and lifetimes from a run's compositions, and
niches (distinct capabilities) of a team.

A run's history is one composition record per generation, ``{"generation": g, "population":
{species id: individuals}, "team": {species id: robots}}``. Species ids are never reused, so a
species is *founded* in the first generation it appears in and goes *extinct* in the first
generation after its last. Pure functions over plain records: the live run and the offline
analysis of a run directory (`swarmcode-torch dynamics`) share them.
"""

from __future__ import annotations

import statistics
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field


@dataclass
class Turnover:
    """The species bookkeeping carried from generation to generation.

    alive: species ids in the last generation seen; born: id -> generation of founding, for
    every species seen (kept after extinction, for lifetimes); died: id -> generation of
    extinction (the first generation without it)."""

    alive: frozenset[int] = frozenset()
    born: dict[int, int] = field(default_factory=dict)
    died: dict[int, int] = field(default_factory=dict)

    def copy(self) -> Turnover:
        return Turnover(self.alive, dict(self.born), dict(self.died))

    def advance(self, generation: int, population: Iterable) -> tuple[int, int]:
        """Record the species of one generation; (founded, extinct) in it."""
        now = frozenset(int(s) for s in population)
        new = now - self.alive
        gone = self.alive - now
        for s in new:
            self.born.setdefault(s, generation)
        for s in gone:
            self.died[s] = generation
        self.alive = now
        return len(new), len(gone)

    def ages(self, generation: int, species: Iterable) -> list[int]:
        """Age in generations (0: founded in `generation`) of each of `species`."""
        return [generation - self.born.get(int(s), generation) for s in species]


def median(values: Sequence[float]) -> float:
    """The median of values, NaN for none."""
    return float(statistics.median(values)) if values else float("nan")


def mean_std(values: Sequence[float]) -> tuple[float, float]:
    """The mean of values and their sample standard deviation (0 for a single value): the
    "mean ± std over seeds" of every table."""
    mean = statistics.fmean(values)
    return mean, statistics.stdev(values) if len(values) > 1 else 0.0


def replay(history: Sequence[dict]) -> tuple[Turnover, list[dict]]:
    """The turnover after every record of `history`, and per generation: founded, extinct,
    species (population), team_species, median_age (over the population's species) and
    team_median_age (over the team's species). A resumed run that repeated generations keeps
    the last record of each."""
    by_gen: dict[int, dict] = {}
    for h in history:
        by_gen[int(h["generation"])] = h
    t = Turnover()
    rows = []
    for g in sorted(by_gen):
        h = by_gen[g]
        founded, extinct = t.advance(g, h["population"])
        team = [int(s) for s in h.get("team", {})]
        rows.append(
            {
                "generation": g,
                "founded": founded,
                "extinct": extinct,
                "species": len(h["population"]),
                "team_species": len(team),
                "median_age": median(t.ages(g, h["population"])),
                "team_median_age": median(t.ages(g, team)),
            }
        )
    return t, rows


def lifetimes(t: Turnover, start: int, end: int) -> list[int]:
    """Lifetimes (generations alive) of the species that went extinct in [start, end)."""
    return [d - t.born[s] for s, d in t.died.items() if start <= d < end]


def window_stats(
    rows: Sequence[dict],
    t: Turnover,
    start: int,
    end: int,
    team_niches: dict[int, int] | None = None,
) -> dict:
    """Medians over generations [start, end) of `replay` rows: species in the best team and in
    the population, niches (from `team_niches`: generation -> niches of its best team), founding
    and extinction per generation, median species age, and the median lifetime of the species
    that died in the window. `founded_lasting_per_generation` counts only the species founded
    in the window that were alive in two generations or more (one founded in the last
    generation of `rows` cannot be told yet and does not count): the founding that is not a
    singleton dying at once."""
    win = [r for r in rows if start <= r["generation"] < end]
    n = len(win)
    last = rows[-1]["generation"] if rows else start
    lasting = sum(
        1 for sp, b in t.born.items() if start <= b < end and t.died.get(sp, last + 1) - b >= 2
    )
    niche_of = team_niches or {}
    niches = [niche_of[r["generation"]] for r in win if r["generation"] in niche_of]
    return {
        "generations": n,
        "from": start,
        "to": end,
        "team_species": median([r["team_species"] for r in win]),
        "population_species": median([r["species"] for r in win]),
        "niches": median(niches),
        "founded_per_generation": sum(r["founded"] for r in win) / n if n else float("nan"),
        "founded_lasting_per_generation": lasting / n if n else float("nan"),
        "extinct_per_generation": sum(r["extinct"] for r in win) / n if n else float("nan"),
        "median_age": median([r["median_age"] for r in win]),
        "team_median_age": median([r["team_median_age"] for r in win]),
        "median_lifetime": median(lifetimes(t, start, end)),
    }


def niche_count(capabilities: Iterable[Iterable[int]]) -> int:
    """Distinct non-empty capabilities (each the set of package classes one design can lift)."""
    return len({frozenset(c) for c in capabilities if c})
