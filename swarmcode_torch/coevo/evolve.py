"""SwarmCoDe end to end: one generation = speciation, evaluation, reproduction (paper Sec. III-A).

`Evolution` owns the population and the run's random generator. `step()` advances one
generation and returns its `GenerationResult`; the application's records and reporters
(TensorBoard, summary, checkpoints, progress) consume it. Nothing here prints or writes files.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from functools import partial
from typing import Any

import torch
from torch import Tensor

from ..sim import bt
from ..sim.hardware import Phenotype
from ..sim.runtime import resolve_device, tick_function, tick_mode
from ..sim.scenario import Scenario, load_scenario
from ..sim.state import WorldParams
from . import admission, knockout, partners, refound, shares
from .admission import Admission
from .config import EvalConfig, ReproductionParams, SpeciationParams, SwarmCoDeConfig
from .dynamics import Turnover, median
from .evaluation import EvalResult, ScoreFn, evaluate, plan_evaluation, score_fn_name, team_scores
from .fitness import beats_baseline, ema
from .hooks import AfterEvaluation, AfterReproduction, AfterSpeciation, Hooks
from .hooks import call as call_hooks
from .population import Population, genome_phenotype
from .readout import BestTeam, Readout, read_generation  # noqa: F401 (BestTeam: re-exported)
from .refound import Archive
from .reproduction import Quotas, mutate, mutate_bt, reproduce
from .run_state import (  # noqa: F401 (re-exported: the checkpoint's state dict)
    CHECKPOINT_VERSION,
    EvolutionState,
    GenerationResult,
    load_state_dict,
    state_dict,
)
from .speciation import SpeciationResult, distance, speciate


def random_population(
    n: int, cfg: SwarmCoDeConfig, generator: torch.Generator, device: torch.device
) -> Population:
    """The initial population: random genes, each seeded with a randomised template tree."""
    g = generator
    names = list(bt.TEMPLATES)
    templates = torch.stack([bt.template_tensor(k, cfg.bt_length) for k in names]).to(device)
    which = torch.randint(0, len(names), (n,), generator=g, device=device)
    programs = mutate_bt(templates[which], cfg.reproduction, g)
    return Population.random(n, cfg.tag_length, programs, g, device)


@dataclass
class Context:
    """Run constants derived from the config (not saved; rebuilt on resume)."""

    cfg: SwarmCoDeConfig
    scenario: Scenario
    device: torch.device
    eval_cfg: EvalConfig
    repro: ReproductionParams
    speciation: SpeciationParams
    params: WorldParams
    step_fn: Any
    compiled: bool = False
    evaluator: Any = None
    """Where evaluations are simulated: None, in this process; else an object whose
    `simulate(plan, genome)` returns their per-environment metrics (`evaluation.evaluate`;
    `distributed.ShardedEvaluator` shards them over Ray actors)."""
    score_fn: ScoreFn = team_scores
    """The score of a team-episode (`evaluation.ScoreFn`): the built-in fitness, or the user
    function the run was given (`cfg.fitness_function` names it)."""

    @property
    def tick_mode(self) -> str:
        """How the world tick runs: 'eager', 'compiled', 'compiled, CUDA graphs', or 'eager
        (compiling failed)' once a compiled tick has fallen back."""
        return tick_mode(self.step_fn, self.compiled)


def make_context(
    cfg: SwarmCoDeConfig,
    score_fn: ScoreFn | None = None,
    scenario: Scenario | None = None,
    checked: bool = False,
) -> Context:
    """Validate the config (unless `checked`: the caller has, as the application does once per
    start), load the scenario and pick the device and tick function.
    `score_fn`: a user function that scores team-episodes instead of the built-in fitness (the
    config records its name as `fitness_function`); a config that names one needs it (ValueError).
    `scenario`: the Scenario to run, instead of loading `cfg.scenario` (which then only names
    it)."""
    if score_fn is not None:
        if not callable(score_fn):
            raise TypeError(f"the fitness function must be callable, got {type(score_fn).__name__}")
        cfg = replace(cfg, fitness_function=score_fn_name(score_fn))
    elif cfg.fitness_function is not None:
        raise ValueError(
            f"the run is scored by a custom fitness function "
            f"({cfg.fitness_function}): give the function again"
        )
    if not checked:
        cfg.validate()
    if scenario is None:
        scenario = load_scenario(cfg.scenario)
    device = resolve_device(cfg.device)
    eval_cfg = cfg.evaluation(scenario.num_robots, scenario.episode_ticks)
    step_fn, use_compile = tick_function(device, cfg.compile, cfg.cuda_graphs, cfg.generations)
    # pin the scenario's team size and episode length into the config, so that a saved run keeps
    # them if a built-in scenario's defaults change later
    cfg = replace(cfg, swarm_size=eval_cfg.swarm_size, ticks=eval_cfg.ticks)
    return Context(
        cfg,
        scenario,
        device,
        eval_cfg,
        cfg.reproduction,
        cfg.speciation,
        WorldParams.for_scenario(scenario),
        step_fn,
        use_compile,
        score_fn=score_fn or team_scores,
    )


def new_generator(ctx: Context) -> torch.Generator:
    return torch.Generator(device=ctx.device).manual_seed(ctx.cfg.seed)


def init_state(ctx: Context) -> EvolutionState:
    """Generation 0: a random population, no species yet."""
    g = new_generator(ctx)
    P = ctx.cfg.population
    genome = random_population(P, ctx.cfg, g, ctx.device)
    return EvolutionState(
        generation=0,
        genome=genome,
        species_hint=torch.full((P,), -1, dtype=torch.long, device=ctx.device),
        proto=None,
        proto_ids=torch.zeros(0, dtype=torch.long, device=ctx.device),
        next_species_id=0,
        fitness=torch.zeros(P, device=ctx.device),
        has_fitness=torch.zeros(P, dtype=torch.bool, device=ctx.device),
        rng_state=g.get_state(),
    )


def generation(
    state: EvolutionState, ctx: Context, hooks: Hooks | None = None
) -> tuple[EvolutionState, GenerationResult]:
    """Advance one generation; the new state and what this generation measured. `hooks`:
    observers called after speciation, evaluation and reproduction (`Hooks`). Two values are
    read on the host, each a device sync on a GPU: in speciation (which pairs are within δ)
    and in `readout.read_generation` (what the generation reports, and the number of elites);
    a third with `knockout_pairs` or `team_partners_margin` (the best team's species)."""
    hooks = hooks or Hooks()
    t0 = time.perf_counter()
    g = torch.Generator(device=ctx.device)
    g.set_state(state.rng_state)

    # 1. dynamic speciation
    sp = _speciation(state, ctx)
    arc = refound.observe(
        state.archive,
        sp.species,
        sp.proto_ids,
        state.next_species_id,
        sp.next_species_id,
        state.generation,
        bins=_design_bins(ctx),
    )
    call_hooks(hooks.after_speciation, AfterSpeciation(state.generation, state, sp))
    # the population's phenotype, once a generation: evaluation and the best team read it
    ph = genome_phenotype(state.genome, ctx.scenario.hardware)

    # 2. evaluation of every individual, all teams and trials in one batch
    t_eval = time.perf_counter()
    res, adm = _evaluation(state, ctx, sp, ph, g)
    eval_seconds = time.perf_counter() - t_eval
    fit = ema(state.fitness, res.fitness, state.has_fitness, ctx.cfg.alpha)
    arc = _archive_champions(arc, state, ctx, sp, adm, fit)
    call_hooks(hooks.after_evaluation, AfterEvaluation(state.generation, state, sp, res, fit))

    # 3. reproduction: the quotas (`shares.plan`), the generation's report read with the number of
    # elites they keep, the offspring (`_reproduction`), re-founding copies among them
    trial, tie = refound.on_trial(arc, sp.proto_ids, state.generation), ctx.cfg.best_team_tie
    plan = shares.plan(
        ctx.cfg,
        ctx.repro,
        sp,
        adm,
        fit,
        trial,
        equal=state.generation < ctx.cfg.equal_quotas_until,
        best=shares.best_team_species(res, sp, tie) if ctx.cfg.best_team_floor > 0 else None,
        credit=knockout.best_team_credit(res, sp, state.genome, ph, ctx, g)
        if ctx.cfg.knockout_credit > 0
        else None,
        marginal=shares.basis(ctx.cfg.share_basis, res, fit),
    )
    out = read_generation(state.genome, sp.species, res, ph, fit, plan.n_elite.sum(), tie)
    composition: dict[str, Any] = {"generation": state.generation, "population": out.population}
    composition["team"] = out.team
    if ctx.cfg.team_partners and ctx.cfg.team_partners_margin > 0:  # the next generation's
        composition["needed"] = knockout.needed_ids(res, sp, state.genome, ph, ctx, g)
    turnover = state.turnover.copy()
    founded, extinct = turnover.advance(state.generation, composition["population"])
    new_state, is_elite, parent = _reproduction(state, ctx, sp, fit, plan, out.n_elites, g)
    new_state, arc = _refound(new_state, ctx, arc, fit, parent, is_elite, state.generation, g)
    new_state = replace(
        new_state,
        history=state.history + [composition],
        turnover=turnover,
        admission=adm,
        archive=arc,
    )
    call_hooks(
        hooks.after_reproduction,
        AfterReproduction(state.generation, state, sp, res, fit, new_state, is_elite, parent),
    )

    # 4. what the generation measured
    counts = (founded, extinct)
    times = (t0, eval_seconds, res.sim_seconds)
    return new_state, _measured(state, ctx, out, turnover, counts, composition, times)


def _measured(
    state: EvolutionState,
    ctx: Context,
    out: Readout,
    turnover: Turnover,
    counts: tuple[int, int],
    composition: dict[str, Any],
    times: tuple[float, float, float],
) -> GenerationResult:
    """Step 4: the generation's `GenerationResult` from its report (`out`, read by
    `readout.read_generation`), the species founded and extinct (`counts`), the species' ages
    (`turnover`) and `times`: when the generation started (`time.perf_counter`), the seconds of
    its evaluation and of the rollout."""
    founded, extinct = counts
    t0, eval_seconds, sim_seconds = times
    return GenerationResult(
        generation=state.generation,
        best_fitness=out.fit_max,
        mean_fitness=out.fit_mean,
        num_species=len(out.population),
        founded=founded,
        extinct=extinct,
        species_median_age=median(turnover.ages(state.generation, composition["population"])),
        best_team=out.best_team,
        team_rows=out.team_rows,
        team_median_age=median(turnover.ages(state.generation, composition["team"])),
        focal_max=out.focal_max,
        composition=composition,
        budget=ctx.cfg.budget,
        seconds=time.perf_counter() - t0,
        eval_seconds=eval_seconds,
        sim_seconds=sim_seconds,
        radius=out.radius,
        dominance=out.dominance,
        selectivity=out.selectivity,
    )


def _speciation(state: EvolutionState, ctx: Context) -> SpeciationResult:
    """Step 1: the population's species (`speciation.speciate`)."""
    return speciate(
        state.genome,
        state.species_hint,
        state.proto,
        state.proto_ids,
        state.next_species_id,
        ctx.speciation.delta,
        w=ctx.speciation.weights,
    )


def _evaluation(
    state: EvolutionState, ctx: Context, sp: SpeciationResult, ph: Phenotype, g: torch.Generator
) -> tuple[EvalResult, Admission | None]:
    """Step 2: every individual's scores (`evaluation.evaluate`), and the partner admission
    after them (None where `partner_admission` is "open")."""
    # partners (`admission`): generation 0's species, and a resumed run's without the state
    adm = allowed = designs_d = None
    if ctx.cfg.partner_admission != "open":
        adm = state.admission or Admission.empty(ctx.device).grow(state.next_species_id, True)
        adm = adm.grow(sp.next_species_id, partner=state.generation == 0)
        allowed = adm.allowed(sp.proto_ids)
        w = ctx.speciation.weights
        designs_d = admission.designs(sp.prototypes, w, ctx.cfg.substitute_effector)
    plan = plan_evaluation(
        state.genome,
        sp.species,
        sp.proto_ids,
        sp.proto_index,
        state.fitness,
        state.has_fitness,
        ctx.scenario,
        ctx.eval_cfg,
        g,
        allowed,
        designs_d,
        ph,
        partners.team_partner_mask(state.history, sp.proto_ids) if ctx.cfg.team_partners else None,
    )
    res = evaluate(
        plan,
        state.genome,
        ctx.scenario,
        ctx.eval_cfg,
        ctx.params,
        ctx.step_fn,
        evaluator=ctx.evaluator,
        score_fn=ctx.score_fn,
        phenotype=ph,
    )
    if adm is None:
        return res, None
    assert designs_d is not None and allowed is not None  # both set with `adm`
    gated = ~beats_baseline(res.focal, res.baseline)
    nearest = admission.nearest_partner(designs_d, allowed)
    # a substitute pair: the nearest partner's design within δ of the species' own
    near = admission.near_partner(designs_d, nearest, ctx.speciation.delta)
    if 0 < ctx.cfg.demote_far_after <= state.generation:
        near = near | admission.same_effector(sp.prototypes.effector, nearest)
    adm = admission.update(
        adm,
        sp.species,
        sp.proto_ids,
        gated,
        nearest,
        replace(admission.SUBSTITUTE, clash_generations=ctx.cfg.demote_after),
        near=near,
        elite=state.has_fitness if ctx.cfg.admission_basis == "elites" else None,
    )
    return res, knockout.demote_substitutes(adm, res, sp, state.genome, ph, ctx, g)


def _reproduction(
    state: EvolutionState,
    ctx: Context,
    sp: SpeciationResult,
    fit: Tensor,
    plan: Quotas,
    n_elites: int,
    g: torch.Generator,
) -> tuple[EvolutionState, Tensor, Tensor]:
    """Step 3, the offspring (`reproduction.reproduce` of the `plan`, whose `n_elites` elites are
    known on the host): the next state (its history, turnover and admission still the previous
    generation's), which offspring are elites, and each one's parent."""
    known = sp.distance  # speciation's D of the population, where it computed it
    dist = partial(distance, w=ctx.speciation.weights) if known is None else lambda a, b: known
    children, hint, is_elite, parent = reproduce(
        state.genome,
        fit,
        sp.species,
        sp.proto_index,
        sp.proto_ids,
        ctx.repro,
        g,
        dist,
        plan=plan,
        n_elites=n_elites,
    )
    new_state = EvolutionState(
        generation=state.generation + 1,
        genome=children,
        species_hint=hint,
        proto=sp.prototypes,
        proto_ids=sp.proto_ids,
        next_species_id=sp.next_species_id,
        fitness=torch.where(is_elite, fit[parent], 0.0),
        has_fitness=is_elite,
        rng_state=g.get_state(),
        history=state.history,
        turnover=state.turnover,
        admission=state.admission,
        archive=state.archive,
    )
    return new_state, is_elite, parent


def _archive_champions(
    arc: Archive | None,
    state: EvolutionState,
    ctx: Context,
    sp: SpeciationResult,
    adm: Admission | None,
    fit: Tensor,
) -> Archive | None:
    """Step 2, after the evaluation: with re-founding on (`refound_after`), the champions of
    the partners that beat their baselines archived (a species that dies as one is worth
    re-founding), or with `refound_source = "designs"` the champions alone in their design
    cell; else `arc` as it is."""
    bins = _design_bins(ctx)
    if ctx.cfg.refound_after <= 0 or (adm is None and bins == 0):
        return arc
    useful = None
    if bins == 0 and adm is not None:
        useful = adm.partner & (adm.gated < admission.SUBSTITUTE.admit_below)
    return refound.champions(
        arc,
        state.genome,
        fit,
        sp.species,
        sp.proto_ids,
        useful,
        sp.next_species_id,
        state.generation,
        bins=bins,
    )


def _design_bins(ctx: Context) -> int:
    """The radius bands of re-founding's design cells (`refound_source = "designs"`); 0: the
    archive keeps partners."""
    return refound.REFOUND.size_bins if ctx.cfg.refound_source == "designs" else 0


def _refound(
    new_state: EvolutionState,
    ctx: Context,
    arc: Archive | None,
    fit: Tensor,
    parent: Tensor,
    is_elite: Tensor,
    generation: int,
    g: torch.Generator,
) -> tuple[EvolutionState, Archive | None]:
    """Step 3, its last part: where an archive is kept, the offspring that become copies of an
    archived champion (`refound.inject`; `fit[parent]`: each offspring's parent's fitness), and
    the archive after it."""
    if arc is None:
        return new_state, arc
    arc, children, hint = refound.inject(
        arc,
        new_state.genome,
        new_state.species_hint,
        fit[parent],
        is_elite,
        generation,
        ctx.cfg.refound_after,
        partial(mutate, params=ctx.repro, generator=g),
        bins=_design_bins(ctx),
        explore=refound.explorer(ctx.cfg.refound_source, g),
    )
    return replace(new_state, genome=children, species_hint=hint, rng_state=g.get_state()), arc


class Evolution:
    """A run: config, context and current state; `step()` runs one generation. `fitness`: a
    user `evaluation.ScoreFn` that scores team-episodes instead of the built-in fitness;
    `scenario`: a Scenario object to run instead of loading `cfg.scenario` (`make_context`);
    `checked`: the config has been validated (`SwarmCoDeConfig.validate`). `hooks`: observers
    of each generation's steps (`Hooks`)."""

    def __init__(
        self,
        cfg: SwarmCoDeConfig,
        state: EvolutionState | None = None,
        fitness: ScoreFn | None = None,
        scenario: Scenario | None = None,
        checked: bool = False,
    ):
        self.ctx = make_context(cfg, fitness, scenario, checked)
        self.cfg = self.ctx.cfg
        self.state = state if state is not None else init_state(self.ctx)
        self.hooks = Hooks()

    @classmethod
    def from_checkpoint(
        cls,
        d: dict,
        cfg: SwarmCoDeConfig,
        fitness: ScoreFn | None = None,
        scenario: Scenario | None = None,
        checked: bool = False,
    ) -> Evolution:
        ev = cls.__new__(cls)
        ev.ctx = make_context(cfg, fitness, scenario, checked)
        ev.cfg = ev.ctx.cfg
        ev.state = load_state_dict(d, ev.ctx)
        ev.hooks = Hooks()
        return ev

    @property
    def done(self) -> bool:
        return self.state.generation >= self.cfg.generations

    def step(self) -> GenerationResult:
        self.state, result = generation(self.state, self.ctx, self.hooks)
        return result

    def state_dict(self) -> dict:
        return state_dict(self.state, self.cfg)
