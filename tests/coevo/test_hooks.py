"""Observer hooks of a generation (`evolve.Hooks`) and the generation's single phenotype."""

import torch

from swarmcode_torch.coevo import evaluation, evolve, population
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.evolve import (
    AfterEvaluation,
    AfterReproduction,
    AfterSpeciation,
    Evolution,
)

TINY = SwarmCoDeConfig(
    scenario="two-niche",
    population=10,
    swarm_size=4,
    trials=1,
    ticks=12,
    generations=3,
    seed=2,
    device="cpu",
    compile=False,
)


def test_hooks_are_called_in_order_once_a_generation_with_what_the_step_has():
    ev = Evolution(TINY)
    calls = []

    def after_speciation(e):
        assert type(e) is AfterSpeciation and e.state is ev.state  # before the step ends
        assert e.generation == e.state.generation
        assert e.speciation.species.shape == (TINY.population,)
        calls.append(("speciation", e.generation, e))

    def after_evaluation(e):
        assert type(e) is AfterEvaluation and e.state is ev.state
        assert e.speciation is calls[-1][2].speciation  # the same species
        assert e.evaluation.fitness.shape == e.fitness.shape == (TINY.population,)
        calls.append(("evaluation", e.generation, e))

    def after_reproduction(e):
        assert type(e) is AfterReproduction and e.state is ev.state
        assert e.evaluation is calls[-1][2].evaluation
        assert e.next_state.generation == e.generation + 1
        assert e.next_state.genome.size == TINY.population == e.is_elite.numel()
        calls.append(("reproduction", e.generation, e))

    ev.hooks.after_speciation.append(after_speciation)
    ev.hooks.after_evaluation.append(after_evaluation)
    ev.hooks.after_reproduction.append(after_reproduction)
    results = []
    while not ev.done:
        results.append(ev.step())
        # the next state the last hook saw is the state the step left
        assert calls[-1][2].next_state is ev.state
    assert [(what, g) for what, g, _ in calls] == [
        (what, g) for g in range(3) for what in ("speciation", "evaluation", "reproduction")
    ]
    for g, r in enumerate(results):
        spec, evaluated, _ = (e for what, gg, e in calls if gg == g)
        # what the hooks got is what the generation reported
        assert r.num_species == int(torch.unique(spec.speciation.species).numel())
        assert r.best_fitness == float(evaluated.fitness.max())


def test_hooks_change_nothing():
    a, b = Evolution(TINY), Evolution(TINY)
    b.hooks.after_evaluation.append(lambda e: None)
    while not a.done:
        ra, rb = a.step(), b.step()
        assert ra.best_fitness == rb.best_fitness
    assert torch.equal(a.state.genome.bt, b.state.genome.bt)


def test_the_phenotype_is_computed_once_a_generation(monkeypatch):
    calls = []
    real = population.genome_phenotype

    def counted(genome, *a, **k):
        calls.append(genome.size)
        return real(genome, *a, **k)

    for mod in (population, evaluation, evolve):
        monkeypatch.setattr(mod, "genome_phenotype", counted)
    ev = Evolution(TINY)
    while not ev.done:
        ev.step()
    assert calls == [TINY.population] * TINY.generations
