"""Baselines for the algorithm comparison: homogeneous GA, fixed-species CCEA, SwarmCoDe wrapper."""

from dataclasses import replace

import pytest
import torch

from swarmcode_torch.baselines import (
    ALGORITHMS,
    FixedSpeciesCCEA,
    HomogeneousGA,
    SwarmCoDeRun,
    compare,
    distinct_per_row,
    evaluate_team,
    fixed_species_ccea,
    homogeneous_ga,
    plan_generations,
    reproduce_groups,
    split_evenly,
    summarize,
    swarmcode,
    swarmcode_no_dominance,
)
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.evolve import random_population
from swarmcode_torch.coevo.population import Population, design_record, genome_phenotype
from swarmcode_torch.sim.step import step as world_step

TINY = SwarmCoDeConfig(
    scenario="four-niche", population=8, swarm_size=5, trials=2, ticks=12, seed=3, device="cpu"
)
CPU = torch.device("cpu")


def gen(seed=0):
    return torch.Generator().manual_seed(seed)


def same_genome(a: Population, b: Population) -> bool:
    return all(torch.equal(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__)


# ------------------------------------------------------------------ helpers
def test_split_evenly():
    assert split_evenly(10, 4) == [3, 3, 2, 2]
    assert split_evenly(8, 4) == [2, 2, 2, 2]
    assert split_evenly(5, 1) == [5]
    assert sum(split_evenly(17, 5)) == 17
    with pytest.raises(ValueError):
        split_evenly(3, 0)


def test_distinct_per_row_ignores_empty_slots():
    teams = torch.tensor([[2, 2, 2], [0, 1, 0], [3, -1, 4], [-1, -1, -1]])
    assert distinct_per_row(teams).tolist() == [1, 2, 2, 0]


# ------------------------------------------------------------------ reproduction
def test_elites_survive_unchanged_first_in_each_group():
    pop = random_population(13, TINY, gen(1), CPU)
    fit = torch.rand(13, generator=gen(2))
    sizes = [8, 5]  # elite_count: 8 -> 2, 5 -> 2 (max_elite 3)
    children, is_elite, parent = reproduce_groups(pop, fit, sizes, 3, gen(3))
    assert children.size == 13
    for start, n in ((0, 8), (8, 5)):
        top = (torch.sort(fit[start : start + n], descending=True, stable=True).indices + start)[:2]
        assert parent[start : start + 2].tolist() == top.tolist()
        assert is_elite[start : start + n].tolist() == [True, True] + [False] * (n - 2)
        assert same_genome(children.index(slice(start, start + 2)), pop.index(top))
        # offspring descend from a parent of their own group
        assert (
            (parent[start : start + n] >= start) & (parent[start : start + n] < start + n)
        ).all()


def test_offspring_are_mutated_not_copies():
    pop = random_population(10, TINY, gen(1), CPU)
    children, is_elite, parent = reproduce_groups(pop, torch.arange(10.0), [10], 3, gen(4))
    off = (~is_elite).nonzero().flatten()
    # every offspring has its continuous genes perturbed (gaussian noise on every gene)
    assert not torch.equal(children.radius[off], pop.radius[parent[off]])


def test_reproduce_groups_rejects_bad_sizes():
    pop = random_population(6, TINY, gen(1), CPU)
    with pytest.raises(ValueError):
        reproduce_groups(pop, torch.zeros(6), [3, 2], 3, gen(0))


# ------------------------------------------------------------------ homogeneous GA
def test_ga_team_is_s_clones_and_one_species():
    ga = HomogeneousGA(TINY, gen())
    teams = ga.teams()
    assert teams.shape == (8, 5)
    assert (teams == torch.arange(8)[:, None]).all()
    m = ga.step()
    assert m["team/species"] == 1 and m["best/species"] == 1
    assert ga.best.species == 1 and ga.best.genome.size == 1 and ga.best.team.tolist() == [0] * 5
    # its cost is S robots plus the species overhead once
    cost = genome_phenotype(ga.best.genome).cost[0] * 5 + ga.ctx.scenario.species_overhead
    assert ga.best.cost == pytest.approx(float(cost), rel=1e-5)


def test_ga_one_batch_per_generation_and_episode_count():
    ga = HomogeneousGA(TINY, gen())
    shapes = []

    def spy(state, *args):
        shapes.append(tuple(state.pos.shape))
        return world_step(state, *args)

    ga.ctx.step_fn = spy
    for i in range(1, 3):
        m = ga.step()
        assert m["episodes"] == ga.episodes == i * TINY.population * TINY.trials
    assert len(shapes) == 2 * TINY.ticks  # one tick loop per generation
    assert set(shapes) == {(TINY.population * TINY.trials, 5, 2)}


def test_ga_elites_keep_their_score_in_identical_environments():
    # with the environments fixed, the re-evaluated elites score exactly as before, so the best
    # score of a generation can never fall below the previous generation's best
    ga = HomogeneousGA(TINY, gen(5), resample_environments=False)
    prev_best, prev_scores, prev_genome = None, None, None
    for _ in range(3):
        genome = ga.genome
        m = ga.step()
        if prev_best is not None:
            top = torch.sort(prev_scores, descending=True, stable=True).indices[0]
            assert same_genome(genome.index(slice(0, 1)), prev_genome.index(top.view(1)))
            assert float(ga.last_scores[0]) == float(prev_scores[top])
            assert m["team/fitness"] >= prev_best
        prev_best, prev_scores, prev_genome = m["team/fitness"], ga.last_scores, genome
    # the run's best team re-scores to exactly its recorded fitness in those environments
    assert evaluate_team(ga.best, ga.ctx, ga.environments())["score"] == ga.best.fitness


def test_ga_best_so_far_is_monotone_and_metrics_keys():
    ms = list(homogeneous_ga(TINY, 3, gen()))
    assert [m["generation"] for m in ms] == [0, 1, 2]
    best = [m["best"] for m in ms]
    assert best == sorted(best) and best[-1] == max(m["team/fitness"] for m in ms)
    for m in ms:
        assert {"best", "team/fitness", "team/species", "fitness/mean", "episodes"} <= set(m)


# ------------------------------------------------------------------ fixed-species CCEA
@pytest.mark.parametrize("k,slots", [(1, [5]), (2, [3, 2]), (3, [2, 2, 1]), (5, [1] * 5)])
def test_ccea_slot_split_and_teams(k, slots):
    cfg = replace(TINY, population=10)
    cc = FixedSpeciesCCEA(cfg, k, gen())
    assert cc.slots == slots and sum(cc.slots) == 5
    assert cc.sizes == split_evenly(10, k)
    teams = cc.teams()
    for i in range(10):
        s = int(cc.species[i])
        assert int((teams[i] == i).sum()) == slots[s]  # its own species' slots
        for j in range(k):
            if j != s:  # the others' representatives
                sel = cc.slot_species == j
                assert (teams[i][sel] == cc.representatives[j]).all()
                assert int(cc.species[cc.representatives[j]]) == j
    assert (distinct_per_row(teams) == k).all()


def test_ccea_steps_episodes_and_representatives():
    cc = FixedSpeciesCCEA(TINY, 2, gen())
    for i in range(1, 3):
        m = cc.step()
        assert m["episodes"] == i * TINY.population * TINY.trials
        assert m["team/species"] == 2 and cc.best.species == 2
        # next representatives: the first row of each block, the best of the generation
        assert cc.representatives.tolist() == [0, 4]
        for j, start in enumerate((0, 4)):
            block = cc.last_scores[start : start + 4]
            assert int(cc.species[start]) == j and block.numel() == 4
    ms = list(fixed_species_ccea(TINY, 2, 1, gen()))
    assert ms[-1]["episodes"] == TINY.population * TINY.trials


def test_ccea_rejects_bad_species_counts():
    with pytest.raises(ValueError):
        FixedSpeciesCCEA(TINY, 6, gen())  # more species than slots
    with pytest.raises(ValueError):
        FixedSpeciesCCEA(replace(TINY, population=6), 4, gen())  # < 2 individuals per species


# ------------------------------------------------------------------ SwarmCoDe wrapper
def test_swarmcode_wrapper_matches_evolution_and_counts_episodes():
    run = SwarmCoDeRun(TINY)
    from swarmcode_torch.app.records import team_record

    best = None
    for i in range(1, 3):
        m = run.step()
        full = run.last_result
        team = team_record(full.best_team, full.generation, run.evolution.ctx.scenario)
        best = team if best is None or team["fitness"] > best["fitness"] else best
        assert m["episodes"] == i * 2 * TINY.population * TINY.trials
        assert m["best"] == best["fitness"] == run.best.fitness
        assert m["team/species"] == team["species"]
    # the recovered best team has exactly the recorded designs and slot counts
    assert run.best.species == best["species"] and run.best.team.numel() == 5
    counts = torch.bincount(run.best.team, minlength=run.best.genome.size).tolist()
    cost = genome_phenotype(run.best.genome).cost
    got = sorted(
        (design_record(run.best.genome, r, 0, float(cost[r]))["bt"], counts[r])
        for r in range(run.best.genome.size)
    )
    want = sorted((d["bt"], d["count"]) for d in best["designs"])
    assert got == want


def test_no_dominance_variant_sets_the_flag():
    assert SwarmCoDeRun(TINY, dominance=False).evolution.cfg.dominance is False
    assert SwarmCoDeRun(TINY, dominance=False).name == "swarmcode-no-dominance"
    ms = list(swarmcode_no_dominance(TINY, 1))
    assert ms[0]["episodes"] == 2 * TINY.population * TINY.trials
    assert len(list(swarmcode(TINY, 1))) == 1


# ------------------------------------------------------------------ compare
def test_plan_gives_equal_budgets():
    plan = plan_generations(2 * 8 * 2 * 5, 8, 2)
    assert plan["swarmcode"] == plan["swarmcode-no-dominance"] == 5
    assert plan["homogeneous-ga"] == plan["ccea"] == 10
    with pytest.raises(ValueError):
        plan_generations(2 * 8 * 2 * 5 + 1, 8, 2)


COMPARE = dict(
    scenario="four-niche",
    seeds=[1],
    generations=1,
    population=4,
    swarm_size=3,
    trials=1,
    ticks=6,
    device="cpu",
    num_species=2,
    eval_trials=2,
)


def test_compare_equal_episodes_and_deterministic():
    rows = compare(**COMPARE)
    assert [r["algorithm"] for r in rows] == list(ALGORITHMS)
    assert {r["episodes"] for r in rows} == {2 * 4 * 1}
    gens = {r["algorithm"]: r["generations"] for r in rows}
    assert gens["homogeneous-ga"] == gens["ccea"] == 2 * gens["swarmcode"] == 2
    by = {r["algorithm"]: r for r in rows}
    assert by["homogeneous-ga"]["species"] == 1 and by["ccea"]["species"] == 2
    assert all(r["seed"] == 1 for r in rows)
    again = compare(**COMPARE)  # same seed: the same results
    strip = lambda r: {k: v for k, v in r.items() if k != "seconds"}  # noqa: E731
    assert [strip(r) for r in again] == [strip(r) for r in rows]


def test_ga_and_ccea_same_seed_same_run_different_seed_differs():
    a = [m["best"] for m in homogeneous_ga(TINY, 2, gen(7))]
    b = [m["best"] for m in homogeneous_ga(TINY, 2, gen(7))]
    assert a == b
    ca = FixedSpeciesCCEA(TINY, 2, gen(7))
    cb = FixedSpeciesCCEA(TINY, 2, gen(8))
    assert not same_genome(ca.genome, cb.genome)


def test_summarize_mean_and_sample_std():
    rows = [
        dict(
            algorithm="a",
            seed=s,
            episodes=8,
            generations=1,
            best_fitness=v,
            heldout_fitness=v,
            heldout_deliveries=0.0,
            species=1,
            team_cost=10.0,
            seconds=1.0,
        )
        for s, v in ((0, 1.0), (1, 3.0))
    ]
    (t,) = summarize(rows)
    assert t["best_fitness"] == 2.0 and t["best_fitness_std"] == pytest.approx(2**0.5)
    assert t["seeds"] == 2 and t["species_std"] == 0.0
