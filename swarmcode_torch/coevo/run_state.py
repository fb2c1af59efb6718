"""The state of a run: `EvolutionState` (what a checkpoint holds) and `GenerationResult` (what
one generation measured); `coevo.evolve` re-exports both."""

from __future__ import annotations

from dataclasses import dataclass, field

from torch import Tensor

from .admission import Admission
from .dynamics import Turnover
from .population import Population
from .readout import BestTeam
from .refound import Archive


@dataclass
class EvolutionState:
    """Everything needed to continue a run after `generation` completed generations."""

    generation: int
    genome: Population  # the population to be evaluated next
    species_hint: Tensor  # [P] species inherited from the parent (-1: none)
    proto: Population | None  # previous generation's species prototypes
    proto_ids: Tensor  # [K] their species ids
    next_species_id: int
    fitness: Tensor  # [P] smoothed fitness carried by elites
    has_fitness: Tensor  # [P] bool
    rng_state: Tensor  # the run generator's state
    best: dict | None = None  # the application's record of the run's best team so far
    #                                (`app.records.step` keeps it; saved in checkpoints)
    history: list = field(default_factory=list)  # per-generation composition records
    turnover: Turnover = field(default_factory=Turnover)  # species births and deaths (derived
    #                                                       from history; not saved)
    admission: Admission | None = None  # partner admission by species id (`partner_admission =
    #                                     "substitute"`); None: not used yet
    archive: Archive | None = None  # re-founding of extinct partners (`refound_after`); None:
    #                                 not used yet


@dataclass(frozen=True, eq=False)
class GenerationResult:
    """What one generation measured (`generation` returns it; `app.records` turns it into
    TensorBoard tags, metrics.csv rows, summary.json and teams.jsonl)."""

    generation: int  # the generation evaluated (0-based)
    best_fitness: float  # highest smoothed fitness in the population
    mean_fitness: float
    num_species: int  # species in the population
    founded: int  # species founded this generation
    extinct: int  # species gone since the previous generation
    species_median_age: float  # generations since founding, median over the species
    best_team: BestTeam  # this generation's best team
    team_rows: Tensor  # [S] population rows of that team's robots (-1: empty slot)
    team_median_age: float  # median age of the team's species
    focal_max: float  # highest focal team score (ungated)
    composition: dict  # species sizes in the population and in the team
    budget: float | None
    seconds: float  # wall time of the generation
    eval_seconds: float  # of which evaluation
    sim_seconds: float  # of which the rollout (device synchronised)
    radius: Tensor  # [P] genes of the evaluated population, on the CPU
    dominance: Tensor  # [P]
    selectivity: Tensor  # [P]
    team: dict | None = None
    """The application's report record of `best_team` (its teams.jsonl line); None here: the
    algorithm builds no records (`app.records.step` fills it in)."""
    best: dict | None = None
    """The application's record of the best team of the run so far (`app.records.step`)."""
    reeval_seconds: float = 0.0
    """Wall time of the application's re-evaluation of the generation's best team
    (`app.records.step`, `app.best_team`); 0 here."""
