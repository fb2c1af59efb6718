"""The state of a run: `EvolutionState` (what a checkpoint holds), its checkpoint state dict
written and read back (`state_dict`, `load_state_dict`), and `GenerationResult` (what one
generation measured); `coevo.evolve` re-exports them."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import torch
from torch import Tensor

from .admission import Admission
from .config import SwarmCoDeConfig
from .dynamics import Turnover, replay
from .population import Population
from .readout import BestTeam
from .refound import Archive
from .state_check import check_state_dict


class RunContext(Protocol):
    """What reading a checkpoint needs of a run's context (`evolve.Context` is one)."""

    cfg: SwarmCoDeConfig
    device: torch.device


CHECKPOINT_VERSION = 1


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
    TensorBoard tags, metrics.csv rows, summary.json and teams.jsonl).

    `team`, `best` and `reeval_seconds` are the application's: the algorithm leaves them empty
    and `app.records.step` fills them in a copy (`dataclasses.replace`). They stay here so that
    every reporter hook and callback receives one result per generation; the run's best team
    itself is not part of the algorithm's state (the application keeps it, `app.run_record`)."""

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


# ------------------------------------------------------------------ checkpoints
def state_dict(state: EvolutionState, cfg: SwarmCoDeConfig) -> dict:
    """A CPU, torch.save-able snapshot of the run."""
    return {
        "version": CHECKPOINT_VERSION,
        "config": cfg.to_dict(),
        "generation": state.generation,
        "genome": state.genome.state_dict(),
        "species_hint": state.species_hint.cpu(),
        "proto": state.proto.state_dict() if state.proto is not None else None,
        "proto_ids": state.proto_ids.cpu(),
        "next_species_id": state.next_species_id,
        "fitness": state.fitness.cpu(),
        "has_fitness": state.has_fitness.cpu(),
        "rng_state": state.rng_state.cpu(),
        "history": state.history,
        "admission": state.admission.state_dict() if state.admission is not None else None,
        "archive": state.archive.state_dict() if state.archive is not None else None,
    }


def load_state_dict(d: dict, ctx: RunContext) -> EvolutionState:
    """Rebuild a state from `state_dict` output; ValueError if it does not fit this run.
    Entries that are not the algorithm's (the application's, such as an older checkpoint's
    "best") are ignored."""
    if not isinstance(d, dict) or d.get("version") != CHECKPOINT_VERSION:
        raise ValueError("checkpoint has an unknown format or version")
    dev = ctx.device
    check_state_dict(d, ctx.cfg)
    genome = Population.from_state_dict(d["genome"]).to(dev)
    rng = d["rng_state"]
    if rng.numel() != torch.Generator(device=dev).get_state().numel():
        raise ValueError(
            f"checkpoint was written on another kind of device than {dev.type}; "
            "resume it with the --device it was run on"
        )
    try:
        torch.Generator(device=dev).set_state(rng)
    except (RuntimeError, TypeError, ValueError):
        raise ValueError("rng_state is not a valid state of the run's generator") from None
    adm = None
    if d.get("admission") is not None:
        adm = Admission.from_state_dict(d["admission"], dev)
        if adm.partner.numel() != int(d["next_species_id"]):
            raise ValueError("checkpoint's partner admission state does not cover its species")
    arc = None
    if d.get("archive") is not None:
        arc = Archive.from_state_dict(d["archive"], dev)
        if arc.lineage.numel() > int(d["next_species_id"]):
            raise ValueError("checkpoint's re-founding archive covers species it does not have")
    return EvolutionState(
        generation=int(d["generation"]),
        genome=genome,
        species_hint=d["species_hint"].to(dev),
        proto=Population.from_state_dict(d["proto"]).to(dev) if d["proto"] is not None else None,
        proto_ids=d["proto_ids"].to(dev),
        next_species_id=int(d["next_species_id"]),
        fitness=d["fitness"].to(dev),
        has_fitness=d["has_fitness"].to(dev),
        rng_state=rng,
        history=list(d["history"]),
        turnover=replay(d["history"])[0],
        admission=adm,
        archive=arc,
    )
