"""SwarmCoDe's generation step: evaluation batching, generations, the best team, presets
(runs, checkpoints, migrations and records are tested in tests/app/test_runs.py)."""

from dataclasses import replace

import pytest
import torch

from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.evaluation import EvalConfig, evaluate, plan_evaluation
from swarmcode_torch.coevo.evolve import Evolution, random_population
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.step import step as world_step

TINY = SwarmCoDeConfig(
    scenario="one-niche", population=8, swarm_size=5, trials=2, ticks=15, generations=4, seed=1
)


def _planned(pop, cfg, g):
    """`evaluate`'s first arguments for two individuals of two species on one-niche: the plan
    (`plan_evaluation`, drawn from `g`), the genome, the scenario and the config."""
    ids = torch.tensor([0, 1])
    zeros = torch.zeros(2)
    world = load_scenario("one-niche")
    plan = plan_evaluation(pop, ids, ids, ids, zeros, zeros.bool(), world, cfg, g)
    return plan, pop, world, cfg


def _two_identical(cfg=TINY):
    g = torch.Generator().manual_seed(0)
    pop = random_population(1, cfg, g, torch.device("cpu"))
    pop = pop.index(torch.tensor([0, 0]))
    pop.tag[:] = True
    pop.selectivity[:] = 1.0
    return pop


def test_all_focal_and_baseline_trials_run_as_one_batch():
    pop = _two_identical()
    seen = []

    def spy(state, *args):
        seen.append(state.pos.shape)
        return world_step(state, *args)

    cfg = EvalConfig(swarm_size=5, trials=3, ticks=7)
    evaluate(*_planned(pop, cfg, torch.Generator().manual_seed(0)), step_fn=spy)
    assert len(seen) == 7  # one tick loop
    assert all(s == (2 * 2 * 3, 5, 2) for s in seen)  # 2 individuals x (focal, baseline) x 3 trials


def test_identical_partner_gives_zero_marginal_and_gated_fitness():
    # the paper's refill: the baseline replaces the focal by an identical design in identical
    # environments, so both teams score exactly the same and the gate applies to both
    pop = _two_identical()
    cfg = EvalConfig(swarm_size=6, trials=2, ticks=60)
    res = evaluate(*_planned(pop, cfg, torch.Generator().manual_seed(4)))
    assert (res.swarms.baseline_team[0] == 1).all() and (res.swarms.baseline_team[1] == 0).all()
    assert torch.equal(res.focal, res.baseline)
    assert torch.allclose(res.fitness, res.focal * cfg.p_marginal)


def test_alone_an_individual_beats_an_empty_baseline():
    pop = _two_identical()
    pop.selectivity[:] = 0.0  # no partners: the baseline team is empty
    cfg = EvalConfig(swarm_size=4, trials=1, ticks=30)
    res = evaluate(*_planned(pop, cfg, torch.Generator().manual_seed(4)))
    assert (res.swarms.baseline_team == -1).all() and (res.swarms.focal_team >= 0).all()
    assert torch.allclose(res.baseline, torch.full((2,), 0.1))  # floor of an empty team's score
    assert (res.fitness == res.focal).all()


def test_generations_keep_population_and_report_metrics():
    ev = Evolution(TINY)
    for _ in range(3):
        m = ev.step()
        assert ev.state.genome.size == TINY.population
        t = m.best_team
        assert m.num_species >= 1 and t.rows.numel() >= 1
        assert int(t.count.sum()) == TINY.swarm_size == int((m.team_rows >= 0).sum())
        assert torch.equal(t.rows, torch.unique(m.team_rows[m.team_rows >= 0]))
        assert m.best_fitness >= m.mean_fitness > 0
        assert t.cost > 0 and int(t.focal.sum()) == 1
        assert m.team is None and m.best is None  # the algorithm builds no records
    assert ev.state.generation == 3 and len(ev.state.history) == 3


def test_roi_objective_divides_by_cost():
    ev = Evolution(replace(TINY, objective="roi"))
    m = ev.step()
    assert m.best_team.fitness < 1.0  # fitness (~100s) divided by a team cost (~$500+)


def test_swarm_larger_than_the_population():
    ev = Evolution(replace(TINY, population=4, swarm_size=12, generations=2))
    for _ in range(2):
        m = ev.step()
        assert int(m.best_team.count.sum()) == 12
        assert m.team_rows.shape == (12,) and int(m.team_rows.max()) < 4


def test_best_team_is_the_team_of_the_fittest_individual():
    """The generation's best team is the focal team of the highest gated fitness, which need not
    be the highest focal team score (a focal that weakens its team is penalised). In odd
    generations a hook sets every individual's gated fitness to minus its focal score (after
    the smoothed fitness is taken, so evolution is unchanged): the best team must then be the
    weakest focal team, whatever the run draws."""
    seen = {}

    def plant(e):
        seen.update(r=e.evaluation)
        if e.generation % 2:
            e.evaluation.fitness.copy_(-e.evaluation.focal)

    ev = Evolution(
        SwarmCoDeConfig(
            scenario="two-niche",
            population=12,
            swarm_size=6,
            trials=1,
            ticks=40,
            generations=6,
            seed=1,
            device="cpu",
            compile=False,
            bt_mutation_rate=1.0,
            p_gene_mutation=1.0,
            partners_per_niche="all",
            quota_size_exponent=None,
        )
    )
    ev.hooks.after_evaluation.append(plant)
    while not ev.done:
        m = ev.step()
        r = seen["r"]
        b = int(r.fitness.argmax())
        assert torch.equal(m.team_rows, r.swarms.focal_team[b])
        assert m.best_team.fitness == pytest.approx(float(r.focal[b]))
        assert m.focal_max == pytest.approx(float(r.focal.max()))
        if m.generation % 2:
            assert b == int((-r.focal).argmax())
            assert m.best_team.fitness == pytest.approx(float(r.focal.min()))


def test_cuda_graphs_need_cuda_and_the_compiled_tick():
    from swarmcode_torch.coevo.evolve import make_context

    with pytest.raises(ValueError, match="cuda_graphs needs device cuda"):
        make_context(
            SwarmCoDeConfig(scenario="one-niche", population=4, device="cpu", cuda_graphs=True)
        )
    # unset (the default) is "on where the tick runs compiled on CUDA": off on the CPU
    from swarmcode_torch.sim.fused import available

    # not compiled on the CPU: the fused C++ tick where it builds (sim/fused.py)
    for compiled, mode in ((False, "fused" if available() else "eager"), (True, "compiled")):
        ctx = make_context(
            SwarmCoDeConfig(scenario="one-niche", population=4, device="cpu", compile=compiled)
        )
        assert ctx.cfg.cuda_graphs is None and ctx.tick_mode == mode
    # a compiled tick that fell back to eager says so
    ctx = make_context(
        SwarmCoDeConfig(scenario="one-niche", population=4, device="cpu", compile=True)
    )
    ctx.step_fn.error = RuntimeError("no compiler")
    assert ctx.tick_mode == "eager (compiling failed)"


def _patch_niche_knowledge(monkeypatch):
    """Make every name through which the algorithm could learn the scenario's niches raise:
    `sim.state.capabilities` wherever a module of the package has bound it, and the oracle's
    `niche_representatives`."""
    import sys

    def refuse(*a, **k):
        raise AssertionError("the algorithm read the scenario's capabilities")

    patched = 0
    for name, mod in list(sys.modules.items()):
        if name.startswith("swarmcode_torch."):
            for attr in ("capabilities", "niche_representatives", "niche_partners"):
                if callable(getattr(mod, attr, None)):
                    monkeypatch.setattr(mod, attr, refuse)
                    patched += 1
    return patched


@pytest.mark.parametrize("preset,settings", [("default", {}), ("paper", {})])
def test_the_presets_algorithm_reads_no_capabilities_or_niches(monkeypatch, preset, settings):
    from swarmcode_torch.coevo.config import preset_config

    cfg = preset_config(
        preset,
        scenario="two-niche",
        population=12,
        swarm_size=6,
        trials=1,
        ticks=20,
        generations=4,
        seed=3,
        **settings,
    )
    assert _patch_niche_knowledge(monkeypatch) >= 3
    ev = Evolution(cfg)
    while not ev.done:
        r = ev.step()
    assert r.team is None and r.best_team.rows.numel() > 0  # the application's records
    # the diagnostic oracle does read them, so the patch is where the algorithm would look
    oracle = Evolution(replace(cfg, partners_per_niche="one"))
    with pytest.raises(AssertionError, match="capabilities"):
        for _ in range(3):
            oracle.step()


def test_presets_set_the_papers_rules_and_record_their_name():
    from swarmcode_torch.coevo.config import PRESETS, preset_config

    paper = preset_config("paper")
    assert paper.preset == "paper" and paper.partners_per_niche == "all"
    assert (paper.quota_size_exponent, paper.p_effector) == (None, None)
    default = preset_config()
    assert default == SwarmCoDeConfig() and default.partner_admission == "substitute"
    assert default.partners_per_niche == "all"  # no niche oracle by default
    assert paper.partner_admission == "open"
    assert preset_config("paper", seed=4).seed == 4 and set(PRESETS) == {"default", "paper"}
    with pytest.raises(ValueError, match="unknown preset 'nope'"):
        preset_config("nope")
    with pytest.raises(ValueError, match="preset must be"):
        replace(default, preset="nope").validate()
