"""A SwarmCoDe run as the application runs it: checkpoints, resume, Ctrl-C, TensorBoard, the
run's records, settings, and configs saved by earlier versions (the generation step itself is
tested in tests/coevo/test_evolve.py)."""

from dataclasses import replace

import pytest
import tomllib
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from swarmcode_torch.app.reporting import SCALAR_TAGS, TensorBoardReporter
from swarmcode_torch.app.runs import (
    CheckpointReporter,
    SummaryReporter,
    config_to_toml,
    load_checkpoint,
    migrate_config,
    resume,
    run,
    write_config,
)
from swarmcode_torch.app.settings import parse_settings
from swarmcode_torch.coevo.config import DISTANCE_KEYS, SwarmCoDeConfig
from swarmcode_torch.coevo.evolve import Evolution

TINY = SwarmCoDeConfig(
    scenario="one-niche", population=8, swarm_size=5, trials=2, ticks=15, generations=4, seed=1
)


def _same_state(x, y):
    """Two Evolutions hold the same state and the same application record."""
    from swarmcode_torch.app.run_record import app_record

    a, b = x.state, y.state
    for name in ("tag", "bt", "radius", "dominance", "selectivity", "effector", "chassis"):
        assert torch.equal(getattr(a.genome, name), getattr(b.genome, name)), name
    assert torch.equal(a.fitness, b.fitness) and torch.equal(a.species_hint, b.species_hint)
    assert app_record(x).best == app_record(y).best and a.history == b.history


def test_resume_equals_straight_through(tmp_path):
    from swarmcode_torch.app.records import step

    straight = Evolution(TINY)
    while not straight.done:
        step(straight)  # as the application runs it: team records with their niches

    cfg = replace(TINY, generations=2)
    first = Evolution(cfg)
    write_config(tmp_path, cfg)
    run(first, tmp_path, [CheckpointReporter(tmp_path, every=1)])
    resumed = resume(tmp_path, generations=TINY.generations)
    assert resumed.state.generation == 2
    run(resumed, tmp_path, [])
    _same_state(straight, resumed)


@pytest.mark.parametrize("wrapped", [False, True])
def test_ctrl_c_checkpoints_the_last_finished_generation(tmp_path, wrapped):
    # wrapped: the interrupt lands in an extension module's initialisation, which Python
    # reports as an ImportError raised from it (seen with SIGTERM during matplotlib's import)
    class Interrupt:
        def on_start(self, ev):
            pass

        def on_end(self, ev):
            pass

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
    run(
        ev,
        tmp_path,
        [TensorBoardReporter(tmp_path, figure_every=1, render_every=2), SummaryReporter(tmp_path)],
    )
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
    assert [e.step for e in acc.Images("best/replay")] == [2]  # the run's best, at its end
    assert any("config" in t for t in tags["tensors"])


def test_config_saved_before_quota_basis_keeps_its_steps():
    from swarmcode_torch.app.runs import retired_setting
    from swarmcode_torch.coevo.evolve import make_context

    new = SwarmCoDeConfig(scenario="one-niche", population=8)
    legacy = {
        k: v
        for k, v in new.to_dict().items()
        if k
        not in (
            "hw_sigma",
            "social_sigma",
            "p_categorical",
            "quota_size_exponent",
            "partners_per_niche",
            *DISTANCE_KEYS,
        )
    }
    old = SwarmCoDeConfig.from_dict(migrate_config(legacy))
    assert (old.hw_sigma, old.social_sigma, old.p_categorical) == (0.1, 0.1, 0.1)
    assert (old.quota_size_exponent, old.partners_per_niche) == (None, "all")
    # its quotas were the mean's (`quota_basis`, retired) and its d_hw over the tiers
    # (`d_hw_tiers`, retired): this version reads it but cannot run it
    migrated = migrate_config(legacy, keep_retired=True)
    assert (migrated["quota_basis"], migrated["d_hw_tiers"]) == ("mean", True)
    assert "cannot run (last run by swarmcode-torch 0.6.0)" in retired_setting(migrated)
    pinned = make_context(new).cfg  # what a run saves
    assert SwarmCoDeConfig.from_dict(pinned.to_dict()) == pinned  # a current config round-trips
    repro = make_context(old).repro
    assert (repro.hw_sigma, repro.p_categorical) == (0.1, 0.1)
    with pytest.raises(ValueError, match="p_categorical"):
        SwarmCoDeConfig(p_categorical=1.5).validate()


def test_runs_pin_the_episode_and_old_configs_keep_250_ticks(tmp_path):
    from swarmcode_torch.app.runs import read_config, write_config
    from swarmcode_torch.coevo.evolve import make_context

    # a new run saves the scenario's episode length and team size, so later scenario changes
    # cannot alter it
    ev = Evolution(
        SwarmCoDeConfig(
            scenario="four-niche", population=4, generations=1, device="cpu", compile=False
        )
    )
    assert (
        (ev.cfg.ticks, ev.cfg.swarm_size)
        == (200, 20)
        == (ev.ctx.eval_cfg.ticks, ev.ctx.eval_cfg.swarm_size)
    )
    write_config(tmp_path, ev.cfg)
    assert read_config(tmp_path).ticks == 200
    # a config saved before runs pinned it ran the niche scenarios' episode of that time
    old = {
        k: v
        for k, v in SwarmCoDeConfig(scenario="four-niche").to_dict().items()
        if k not in ("ticks", *DISTANCE_KEYS)
    }
    assert make_context(SwarmCoDeConfig.from_dict(migrate_config(old))).eval_cfg.ticks == 250
    old["scenario"] = "budget"  # unchanged scenario: its own
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
    old = SwarmCoDeConfig.from_dict(
        migrate_config(
            {k: v for k, v in new.to_dict().items() if k not in ("min_share", *DISTANCE_KEYS)}
        )
    )
    assert old.min_share == 0.0 and make_context(old).repro.min_share == 0.0


def test_config_saved_before_the_paper_text_fixes_keeps_the_old_rates():
    from swarmcode_torch.app.runs import retired_setting
    from swarmcode_torch.coevo.evolve import make_context

    new = SwarmCoDeConfig(scenario="one-niche", population=8)
    ctx = make_context(new)
    assert (ctx.repro.bt_mutation_rate, ctx.repro.p_gene_mutation) == (0.5, 0.2)
    saved = {
        k: v
        for k, v in new.to_dict().items()
        if k not in ("bt_mutation_rate", "p_gene_mutation", *DISTANCE_KEYS)
    }
    ctx = make_context(SwarmCoDeConfig.from_dict(migrate_config(saved)))
    assert (ctx.repro.bt_mutation_rate, ctx.repro.p_gene_mutation) == (1.0, 1.0)
    # its d_hw over the tiers (`d_hw_tiers`, retired) is read, not run
    assert "d_hw_tiers = True" in retired_setting(migrate_config(saved, keep_retired=True))


def test_config_saved_before_0_4_keeps_every_partner_and_its_quota_rule():
    from swarmcode_torch.coevo.evolve import make_context

    new = SwarmCoDeConfig(scenario="one-niche", population=8, partners_per_niche="one")
    ctx = make_context(new)
    assert (ctx.eval_cfg.partners_per_niche, ctx.repro.quota_size_exponent) == ("one", 0.75)
    saved = {
        k: v
        for k, v in new.to_dict().items()
        if k not in ("partners_per_niche", "quota_size_exponent", *DISTANCE_KEYS)
    }  # 0.3.2
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
    assert (
        SwarmCoDeConfig.from_dict(migrate_config({**saved, "p_effector": 0.01})).p_effector == 0.01
    )
    for value in (None, 0.005, 0.0):
        text = config_to_toml(replace(new, p_effector=value))
        back = SwarmCoDeConfig.from_dict(migrate_config(tomllib.loads(text)))
        assert back.p_effector == value


def test_parse_settings_types_and_refusals():
    from swarmcode_torch.app.settings import parse_settings

    assert parse_settings(["delta=0.5", "max-elite=2", "dominance=False", "w_tag=2"]) == {
        "delta": 0.5,
        "max_elite": 2,
        "dominance": False,
        "w_tag": 2.0,
    }
    # a key that may be unset takes none; one that may not refuses it
    assert parse_settings(["quota_size_exponent=none", "p_effector=None"]) == {
        "quota_size_exponent": None,
        "p_effector": None,
    }
    for bad, needle in (
        ("max_elite=2.5", "type int"),
        ("dominance=yes", "type bool"),
        ("delta=none", "type float"),
        ("=3", "KEY=VALUE"),
        ("budget=9", "--budget option"),
        ("quota_basis=mean", "unknown key"),
    ):
        with pytest.raises(ValueError, match=needle):
            parse_settings([bad])


def test_the_application_adds_capabilities_and_niches_to_the_records():
    from swarmcode_torch.app.records import design_capabilities, step
    from swarmcode_torch.coevo.dynamics import niche_count

    ev = Evolution(replace(TINY, scenario="two-niche"))
    r = step(ev)
    designs = r.team["designs"]
    caps = design_capabilities(
        [{k: v for k, v in d.items() if k != "capability"} for d in designs], ev.ctx.scenario
    )
    assert [d["capability"] for d in designs] == caps
    assert r.team["niches"] == niche_count(caps) and "niches" in r.best


def test_cuda_graphs_is_a_bool_setting_written_only_when_chosen():
    assert parse_settings(["cuda_graphs=false"]) == {"cuda_graphs": False}
    assert parse_settings(["cuda_graphs=TRUE"]) == {"cuda_graphs": True}
    with pytest.raises(ValueError, match="cuda_graphs: expected a value of type bool"):
        parse_settings(["cuda_graphs=auto"])
    # unset is not written, so a resumed run decides again on its device; a choice is kept
    assert "cuda_graphs" not in config_to_toml(SwarmCoDeConfig())
    assert "cuda_graphs = false" in config_to_toml(SwarmCoDeConfig(cuda_graphs=False))


def test_a_config_saved_before_0_6_admits_every_partner_and_names_no_preset():
    default = SwarmCoDeConfig()
    old = {
        k: v
        for k, v in default.to_dict().items()
        if k not in ("partner_admission", "preset", *DISTANCE_KEYS)
    }
    cfg = SwarmCoDeConfig.from_dict(migrate_config(old))
    assert (cfg.partner_admission, cfg.preset) == ("open", None)


def test_a_config_written_before_demote_after_resumes_with_the_0_7_rule():
    """Configs written before `demote_after` existed demoted after 2 generations."""
    from swarmcode_torch.coevo.config import SwarmCoDeConfig

    saved = SwarmCoDeConfig(demote_after=6).to_dict()
    del saved["demote_after"]
    assert SwarmCoDeConfig.from_dict(migrate_config(saved)).demote_after == 2
