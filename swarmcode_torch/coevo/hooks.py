"""Observers of a generation's steps (`Hooks`, `evolve.Evolution.hooks`) and what each receives."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from torch import Tensor

from .evaluation import EvalResult
from .speciation import SpeciationResult

if TYPE_CHECKING:
    from .run_state import EvolutionState


@dataclass(frozen=True, eq=False)
class AfterSpeciation:
    """What a generation has after its speciation (`Hooks.after_speciation`)."""

    generation: int  # the generation (0-based)
    state: EvolutionState  # the state it started from (its population: `state.genome`)
    speciation: SpeciationResult  # the population's species and prototypes


@dataclass(frozen=True, eq=False)
class AfterEvaluation(AfterSpeciation):
    """... and after its evaluation (`Hooks.after_evaluation`)."""

    evaluation: EvalResult  # every individual's scores and teams
    fitness: Tensor  # [P] the smoothed fitness reproduction selects by


@dataclass(frozen=True, eq=False)
class AfterReproduction(AfterEvaluation):
    """... and after its reproduction (`Hooks.after_reproduction`)."""

    next_state: EvolutionState  # the state of the next generation (its offspring, their
    #                                species hints, the prototypes)
    is_elite: Tensor  # [P] bool: the offspring copied unchanged
    parent: Tensor  # [P] each offspring's (first) parent, a row of state.genome


@dataclass
class Hooks:
    """Observers of a generation, called in order after each of its three steps with what the
    step has at that point: `after_speciation(AfterSpeciation)`,
    `after_evaluation(AfterEvaluation)`, `after_reproduction(AfterReproduction)`, each once per
    generation. What they receive is the algorithm's own state: read it, never change it.
    Register one with `evolution.hooks.after_speciation.append(fn)`."""

    after_speciation: list[Callable[[AfterSpeciation], None]] = field(default_factory=list)
    after_evaluation: list[Callable[[AfterEvaluation], None]] = field(default_factory=list)
    after_reproduction: list[Callable[[AfterReproduction], None]] = field(default_factory=list)


def call(hooks: list, event) -> None:
    """Each observer of `hooks`, in order, with `event`."""
    for fn in hooks:
        fn(event)
