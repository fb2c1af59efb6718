"""SwarmCoDe end to end: evaluation batching, generations, checkpoints, resume, TensorBoard."""

from dataclasses import replace
import tomllib

import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from swarmcode_torch.coevo.evaluation import EvalConfig, evaluate
from swarmcode_torch.app.runs import migrate_config
from swarmcode_torch.coevo.evolve import Evolution, random_population
from swarmcode_torch.coevo.config import DISTANCE_KEYS, SwarmCoDeConfig
from swarmcode_torch.app.reporting import SCALAR_TAGS, TensorBoardReporter
from swarmcode_torch.app.runs import (CheckpointReporter, SummaryReporter, load_checkpoint, resume,
                                      run, write_config)
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.step import step as world_step

TINY = SwarmCoDeConfig(scenario="one-niche", population=8, swarm_size=5, trials=2, ticks=15,
                    generations=4, seed=1)


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
    evaluate(pop, torch.tensor([0, 1]), torch.tensor([0, 1]), torch.tensor([0, 1]),
             torch.zeros(2), torch.zeros(2, dtype=torch.bool), load_scenario("one-niche"), cfg,
             torch.Generator().manual_seed(0), step_fn=spy)
    assert len(seen) == 7                       # one tick loop
    assert all(s == (2 * 2 * 3, 5, 2) for s in seen)  # 2 individuals x (focal, baseline) x 3 trials


def test_identical_partner_gives_zero_marginal_and_gated_fitness():
    # the paper's refill: the baseline replaces the focal by an identical design in identical
    # environments, so both teams score exactly the same and the gate applies to both
    pop = _two_identical()
    cfg = EvalConfig(swarm_size=6, trials=2, ticks=60)
    res = evaluate(pop, torch.tensor([0, 1]), torch.tensor([0, 1]), torch.tensor([0, 1]),
                   torch.zeros(2), torch.zeros(2, dtype=torch.bool), load_scenario("one-niche"),
                   cfg, torch.Generator().manual_seed(4))
    assert (res.swarms.baseline_team[0] == 1).all() and (res.swarms.baseline_team[1] == 0).all()
    assert torch.equal(res.focal, res.baseline)
    assert torch.allclose(res.fitness, res.focal * cfg.p_marginal)


def test_alone_an_individual_beats_an_empty_baseline():
    pop = _two_identical()
    pop.selectivity[:] = 0.0  # no partners: the baseline team is empty
    cfg = EvalConfig(swarm_size=4, trials=1, ticks=30)
    res = evaluate(pop, torch.tensor([0, 1]), torch.tensor([0, 1]), torch.tensor([0, 1]),
                   torch.zeros(2), torch.zeros(2, dtype=torch.bool), load_scenario("one-niche"),
                   cfg, torch.Generator().manual_seed(4))
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
        assert m.team is None and m.best is None       # the algorithm builds no records
    assert ev.state.generation == 3 and len(ev.state.history) == 3


def test_roi_objective_divides_by_cost():
    ev = Evolution(replace(TINY, objective="roi"))
    m = ev.step()
    assert m.best_team.fitness < 1.0  # fitness (~100s) divided by a team cost (~$500+)


def _same_state(a, b):
    for name in ("tag", "bt", "radius", "dominance", "selectivity", "effector", "chassis"):
        assert torch.equal(getattr(a.genome, name), getattr(b.genome, name)), name
    assert torch.equal(a.fitness, b.fitness) and torch.equal(a.species_hint, b.species_hint)
    assert a.best == b.best and a.history == b.history


def test_resume_equals_straight_through(tmp_path):
    from swarmcode_torch.app.records import step

    straight = Evolution(TINY)
    while not straight.done:
        step(straight)          # as the application runs it: team records with their niches

    cfg = replace(TINY, generations=2)
    first = Evolution(cfg)
    write_config(tmp_path, cfg)
    run(first, tmp_path, [CheckpointReporter(tmp_path, every=1)])
    resumed = resume(tmp_path, generations=TINY.generations)
    assert resumed.state.generation == 2
    run(resumed, tmp_path, [])
    _same_state(straight.state, resumed.state)


@pytest.mark.parametrize("wrapped", [False, True])
def test_ctrl_c_checkpoints_the_last_finished_generation(tmp_path, wrapped):
    # wrapped: the interrupt lands in an extension module's initialisation, which Python
    # reports as an ImportError raised from it (seen with SIGTERM during matplotlib's import)
    class Interrupt:
        def on_start(self, ev): pass
        def on_end(self, ev): pass

        def on_generation(self, ev, metrics):
            if ev.state.generation == 2:
                if not wrapped:
                    raise KeyboardInterrupt
                try:
                    raise KeyboardInterrupt
                except KeyboardInterrupt as e:
                    raise ImportError("initialization failed") from e

    # after the records' step (the reporters past the CheckpointReporter): generation 2 is whole
    ev = Evolution(TINY)
    write_config(tmp_path, TINY)
    with pytest.raises(KeyboardInterrupt):
        run(ev, tmp_path, [CheckpointReporter(tmp_path, every=100), Interrupt()])
    assert load_checkpoint(tmp_path)["generation"] == 2
    assert resume(tmp_path).state.generation == 2
    # inside the records' step (no CheckpointReporter: every reporter records): generation 1's
    # records may be half written, so the checkpoint is of the last generation recorded whole
    (tmp_path / "checkpoint.pt").unlink()
    ev = Evolution(TINY)
    with pytest.raises(KeyboardInterrupt):
        run(ev, tmp_path, [Interrupt()])
    assert load_checkpoint(tmp_path)["generation"] == 1


def test_interrupt_of_finds_an_interrupt_in_the_chain_only():
    from swarmcode_torch.app.runs import interrupt_of

    k = KeyboardInterrupt()
    assert interrupt_of(k) is k
    try:
        try:
            raise k
        except KeyboardInterrupt as e:
            raise ImportError("initialization failed") from e
    except ImportError as e:
        assert interrupt_of(e) is k
    assert interrupt_of(ImportError("no module")) is None
    assert interrupt_of(RuntimeError("x")) is None


def test_tensorboard_tags_read_back(tmp_path):
    ev = Evolution(replace(TINY, generations=3, budget=800.0))
    write_config(tmp_path, ev.cfg)
    run(ev, tmp_path, [TensorBoardReporter(tmp_path, figure_every=1, render_every=2),
                       SummaryReporter(tmp_path)])
    acc = EventAccumulator(str(tmp_path), size_guidance={"images": 0, "histograms": 0})
    acc.Reload()
    tags = acc.Tags()
    for tag in SCALAR_TAGS:
        assert tag in tags["scalars"], tag
        assert [e.step for e in acc.Scalars(tag)] == [0, 1, 2]
    assert acc.Scalars("team/budget")[0].value == 800.0
    assert {"traits/radius", "traits/dominance", "traits/selectivity"} <= set(tags["histograms"])
    assert "species/composition" in tags["images"]
    # one numbering: replays of generations 0, 2, 4 ... for render_every=2, at their own steps
    assert [e.step for e in acc.Images("team/replay")] == [0, 2]
    assert [e.step for e in acc.Images("best/replay")] == [2]     # the run's best, at its end
    assert any("config" in t for t in tags["tensors"])


def test_swarm_larger_than_the_population():
    ev = Evolution(replace(TINY, population=4, swarm_size=12, generations=2))
    for _ in range(2):
        m = ev.step()
        assert int(m.best_team.count.sum()) == 12
        assert m.team_rows.shape == (12,) and int(m.team_rows.max()) < 4


def test_config_saved_before_quota_basis_keeps_its_steps():
    from swarmcode_torch.app.runs import retired_setting
    from swarmcode_torch.coevo.evolve import make_context

    new = SwarmCoDeConfig(scenario="one-niche", population=8)
    legacy = {k: v for k, v in new.to_dict().items()
              if k not in ("hw_sigma", "social_sigma", "p_categorical", "quota_size_exponent",
                           "partners_per_niche", *DISTANCE_KEYS)}
    old = SwarmCoDeConfig.from_dict(migrate_config(legacy))
    assert (old.hw_sigma, old.social_sigma, old.p_categorical) == (0.1, 0.1, 0.1)
    assert (old.quota_size_exponent, old.partners_per_niche) == (None, "all")
    # its quotas were the mean's (`quota_basis`, retired) and its d_hw over the tiers
    # (`d_hw_tiers`, retired): this version reads it but cannot run it
    migrated = migrate_config(legacy, keep_retired=True)
    assert (migrated["quota_basis"], migrated["d_hw_tiers"]) == ("mean", True)
    assert "cannot run (last run by swarmcode-torch 0.6.0)" in retired_setting(migrated)
    pinned = make_context(new).cfg                               # what a run saves
    assert SwarmCoDeConfig.from_dict(pinned.to_dict()) == pinned    # a current config round-trips
    repro = make_context(old).repro
    assert (repro.hw_sigma, repro.p_categorical) == (0.1, 0.1)
    with pytest.raises(ValueError, match="p_categorical"):
        SwarmCoDeConfig(p_categorical=1.5).validate()


def test_runs_pin_the_episode_and_old_configs_keep_250_ticks(tmp_path):
    from swarmcode_torch.coevo.evolve import make_context
    from swarmcode_torch.app.runs import read_config, write_config

    # a new run saves the scenario's episode length and team size, so later scenario changes
    # cannot alter it
    ev = Evolution(SwarmCoDeConfig(scenario="four-niche", population=4, generations=1,
                                device="cpu", compile=False))
    assert (ev.cfg.ticks, ev.cfg.swarm_size) == (200, 20) == (ev.ctx.eval_cfg.ticks,
                                                                ev.ctx.eval_cfg.swarm_size)
    write_config(tmp_path, ev.cfg)
    assert read_config(tmp_path).ticks == 200
    # a config saved before runs pinned it ran the niche scenarios' episode of that time
    old = {k: v for k, v in SwarmCoDeConfig(scenario="four-niche").to_dict().items()
           if k not in ("ticks", *DISTANCE_KEYS)}
    assert make_context(SwarmCoDeConfig.from_dict(migrate_config(old))).eval_cfg.ticks == 250
    old["scenario"] = "budget"                                   # unchanged scenario: its own
    assert make_context(SwarmCoDeConfig.from_dict(migrate_config(old))).eval_cfg.ticks == 250
    old["scenario"] = "swarm200"
    assert make_context(SwarmCoDeConfig.from_dict(migrate_config(old))).eval_cfg.ticks == 500


def test_config_saved_before_p_tag_flip_keeps_one_flip_in_l():
    from swarmcode_torch.coevo.evolve import make_context

    new = SwarmCoDeConfig(scenario="one-niche", population=8, tag_length=8)
    assert make_context(new).repro.p_tag_flip == new.p_tag_flip == 0.01
    old = {k: v for k, v in new.to_dict().items() if k not in ("p_tag_flip", *DISTANCE_KEYS)}
    assert SwarmCoDeConfig.from_dict(migrate_config(old)).p_tag_flip == 1 / 8
    assert make_context(SwarmCoDeConfig.from_dict(migrate_config(old))).repro.p_tag_flip == 1 / 8


def test_config_saved_before_min_share_keeps_every_species_share():
    from swarmcode_torch.coevo.evolve import make_context

    new = SwarmCoDeConfig(scenario="one-niche", population=8)
    assert make_context(new).repro.min_share == new.min_share == 1.0
    old = SwarmCoDeConfig.from_dict(migrate_config({k: v for k, v in new.to_dict().items() if k not in ("min_share", *DISTANCE_KEYS)}))
    assert old.min_share == 0.0 and make_context(old).repro.min_share == 0.0


def test_config_saved_before_the_paper_text_fixes_keeps_the_old_rates():
    from swarmcode_torch.app.runs import retired_setting
    from swarmcode_torch.coevo.evolve import make_context

    new = SwarmCoDeConfig(scenario="one-niche", population=8)
    ctx = make_context(new)
    assert (ctx.repro.bt_mutation_rate, ctx.repro.p_gene_mutation) == (0.5, 0.2)
    saved = {k: v for k, v in new.to_dict().items()
             if k not in ("bt_mutation_rate", "p_gene_mutation", *DISTANCE_KEYS)}
    ctx = make_context(SwarmCoDeConfig.from_dict(migrate_config(saved)))
    assert (ctx.repro.bt_mutation_rate, ctx.repro.p_gene_mutation) == (1.0, 1.0)
    # its d_hw over the tiers (`d_hw_tiers`, retired) is read, not run
    assert "d_hw_tiers = True" in retired_setting(migrate_config(saved, keep_retired=True))


def test_config_saved_before_0_4_keeps_every_partner_and_its_quota_rule():
    from swarmcode_torch.coevo.evolve import make_context

    new = SwarmCoDeConfig(scenario="one-niche", population=8, partners_per_niche="one")
    ctx = make_context(new)
    assert (ctx.eval_cfg.partners_per_niche, ctx.repro.quota_size_exponent) == ("one", 0.75)
    saved = {k: v for k, v in new.to_dict().items()
             if k not in ("partners_per_niche", "quota_size_exponent", *DISTANCE_KEYS)}  # 0.3.2
    ctx = make_context(SwarmCoDeConfig.from_dict(migrate_config(saved)))
    assert (ctx.eval_cfg.partners_per_niche, ctx.repro.quota_size_exponent) == ("all", None)
    # 0.3.3 wrote the exponent ("none" unset; a branch set 0.75): it is kept as written
    for written, kept in (("none", None), (0.75, 0.75)):
        cfg = SwarmCoDeConfig.from_dict(migrate_config({**saved, "quota_size_exponent": written}))
        assert (cfg.partners_per_niche, cfg.quota_size_exponent) == ("all", kept)


def test_config_saved_before_0_5_keeps_the_effector_rate():
    """Before 0.5 an unset p_effector was not written (the effector at p_categorical); 0.5
    writes it always, "none" where it is unset, and a config read back keeps it."""
    from swarmcode_torch.app.runs import config_to_toml
    from swarmcode_torch.coevo.evolve import make_context

    new = SwarmCoDeConfig(scenario="one-niche", population=8)
    assert make_context(new).repro.p_effector == 0.005
    saved = {k: v for k, v in new.to_dict().items() if k not in ("p_effector", *DISTANCE_KEYS)}
    ctx = make_context(SwarmCoDeConfig.from_dict(migrate_config(saved)))
    assert (ctx.repro.p_effector, ctx.repro.p_categorical) == (None, 0.02)
    assert SwarmCoDeConfig.from_dict(migrate_config({**saved, "p_effector": 0.01})).p_effector \
        == 0.01
    for value in (None, 0.005, 0.0):
        text = config_to_toml(replace(new, p_effector=value))
        back = SwarmCoDeConfig.from_dict(migrate_config(tomllib.loads(text)))
        assert back.p_effector == value


def test_parse_settings_types_and_refusals():
    from swarmcode_torch.app.settings import parse_settings

    assert parse_settings(["delta=0.5", "max-elite=2", "dominance=False", "w_tag=2"]) == \
        {"delta": 0.5, "max_elite": 2, "dominance": False, "w_tag": 2.0}
    # a key that may be unset takes none; one that may not refuses it
    assert parse_settings(["quota_size_exponent=none", "p_effector=None"]) == \
        {"quota_size_exponent": None, "p_effector": None}
    for bad, needle in (("max_elite=2.5", "type int"), ("dominance=yes", "type bool"),
                        ("delta=none", "type float"),
                        ("=3", "KEY=VALUE"), ("budget=9", "--budget option"),
                        ("quota_basis=mean", "unknown key")):
        with pytest.raises(ValueError, match=needle):
            parse_settings([bad])


def test_best_team_is_the_team_of_the_fittest_individual():
    """The generation's best team is the focal team of the highest gated fitness, which need not
    be the highest focal team score (a focal that weakens its team is penalised)."""
    seen = {}
    ev = Evolution(SwarmCoDeConfig(scenario="two-niche", population=12, swarm_size=6, trials=1,
                                ticks=40, generations=6, seed=1, device="cpu", compile=False,
                                bt_mutation_rate=1.0, p_gene_mutation=1.0,
                                partners_per_niche="all", quota_size_exponent=None))
    ev.hooks.after_evaluation.append(lambda e: seen.update(r=e.evaluation))
    differed = 0
    while not ev.done:
        m = ev.step()
        r = seen["r"]
        b = int(r.fitness.argmax())
        assert torch.equal(m.team_rows, r.swarms.focal_team[b])
        assert m.best_team.fitness == pytest.approx(float(r.focal[b]))
        assert m.focal_max == pytest.approx(float(r.focal.max()))
        differed += int(int(r.focal.argmax()) != b)
    assert differed > 0         # the two definitions disagree in some generation of this run


def test_cuda_graphs_need_cuda_and_the_compiled_tick():
    from swarmcode_torch.coevo.evolve import make_context
    from swarmcode_torch.app.settings import parse_settings
    from swarmcode_torch.app.runs import config_to_toml

    with pytest.raises(ValueError, match="cuda_graphs needs device cuda"):
        make_context(SwarmCoDeConfig(scenario="one-niche", population=4, device="cpu",
                                  cuda_graphs=True))
    # unset (the default) is "on where the tick runs compiled on CUDA": off on the CPU
    from swarmcode_torch.sim.fused import available
    # not compiled on the CPU: the fused C++ tick where it builds (sim/fused.py)
    for compiled, mode in ((False, "fused" if available() else "eager"), (True, "compiled")):
        ctx = make_context(SwarmCoDeConfig(scenario="one-niche", population=4, device="cpu",
                                        compile=compiled))
        assert ctx.cfg.cuda_graphs is None and ctx.tick_mode == mode
    assert parse_settings(["cuda_graphs=false"]) == {"cuda_graphs": False}
    assert parse_settings(["cuda_graphs=TRUE"]) == {"cuda_graphs": True}
    with pytest.raises(ValueError, match="cuda_graphs: expected a value of type bool"):
        parse_settings(["cuda_graphs=auto"])
    # a compiled tick that fell back to eager says so
    ctx = make_context(SwarmCoDeConfig(scenario="one-niche", population=4, device="cpu",
                                    compile=True))
    ctx.step_fn.error = RuntimeError("no compiler")
    assert ctx.tick_mode == "eager (compiling failed)"
    # unset is not written, so a resumed run decides again on its device; a choice is kept
    assert "cuda_graphs" not in config_to_toml(SwarmCoDeConfig())
    assert "cuda_graphs = false" in config_to_toml(SwarmCoDeConfig(cuda_graphs=False))


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

    cfg = preset_config(preset, scenario="two-niche", population=12, swarm_size=6, trials=1,
                        ticks=20, generations=4, seed=3, **settings)
    assert _patch_niche_knowledge(monkeypatch) >= 3
    ev = Evolution(cfg)
    while not ev.done:
        r = ev.step()
    assert r.team is None and r.best_team.rows.numel() > 0     # the application's records
    # the diagnostic oracle does read them, so the patch is where the algorithm would look
    oracle = Evolution(replace(cfg, partners_per_niche="one"))
    with pytest.raises(AssertionError, match="capabilities"):
        for _ in range(3):
            oracle.step()


def test_the_application_adds_capabilities_and_niches_to_the_records():
    from swarmcode_torch.app.records import design_capabilities, step
    from swarmcode_torch.coevo.dynamics import niche_count

    ev = Evolution(replace(TINY, scenario="two-niche"))
    r = step(ev)
    designs = r.team["designs"]
    caps = design_capabilities([{k: v for k, v in d.items() if k != "capability"}
                                for d in designs], ev.ctx.scenario)
    assert [d["capability"] for d in designs] == caps
    assert r.team["niches"] == niche_count(caps) and "niches" in r.best


def test_presets_set_the_papers_rules_and_record_their_name():
    from swarmcode_torch.coevo.config import PRESETS, preset_config

    paper = preset_config("paper")
    assert paper.preset == "paper" and paper.partners_per_niche == "all"
    assert (paper.quota_size_exponent, paper.p_effector) == (None, None)
    default = preset_config()
    assert default == SwarmCoDeConfig() and default.partner_admission == "substitute"
    assert default.partners_per_niche == "all"          # no niche oracle by default
    assert paper.partner_admission == "open"
    assert preset_config("paper", seed=4).seed == 4 and set(PRESETS) == {"default", "paper"}
    with pytest.raises(ValueError, match="unknown preset 'nope'"):
        preset_config("nope")
    with pytest.raises(ValueError, match="preset must be"):
        replace(default, preset="nope").validate()
    # a config written before 0.6 admits every partner at once and names no preset
    old = {k: v for k, v in default.to_dict().items()
           if k not in ("partner_admission", "preset", *DISTANCE_KEYS)}
    cfg = SwarmCoDeConfig.from_dict(migrate_config(old))
    assert (cfg.partner_admission, cfg.preset) == ("open", None)
