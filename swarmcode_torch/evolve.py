"""SwarmCoDe end to end: one generation = speciation, evaluation, reproduction (paper Sec. III-A).

`Evolution` owns the population and the run's random generator. `step()` advances one
generation and returns its metrics; reporters (TensorBoard, summary, checkpoints, progress)
consume them. Nothing here prints or imports a CLI or logging library.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field, fields, replace
from functools import partial
from typing import Any

import torch
from torch import Tensor

from . import bt
from .dynamics import Turnover, median, niche_count, replay
from .evaluation import EvalConfig, evaluate
from .fitness import FitnessWeights, ema
from .genome import NUM_TIERS, R_MAX, R_MIN, Genome
from .hardware import genome_phenotype
from .reproduction import ReproductionParams, mutate_bt, reproduce
from .scenario import Scenario, load_scenario
from .speciation import DistanceWeights, distance, speciate
from .world import CompiledStep, CudaGraphTicks, WorldParams, capabilities, step as world_step

CHECKPOINT_VERSION = 1
# compiling the tick takes ~10-20 s on a CPU and then runs it ~2.4x faster (benchmarks/README.md)
COMPILE_MIN_GENERATIONS = 50


@dataclass
class EvolveConfig:
    """Everything that defines a run (saved as config.toml in the run directory)."""

    scenario: str = "budget"
    """Built-in scenario name or path to a scenario TOML file."""
    budget: float | None = None
    """Fabrication budget in $; None: no budget penalty."""
    objective: str = "fitness"
    """'fitness' or 'roi' (fitness divided by team cost)."""
    generations: int = 500
    """Total number of generations of the run."""
    population: int = 100
    """Individuals in the evolutionary population."""
    swarm_size: int | None = None
    """Robots per team; None: the scenario's robot count."""
    trials: int = 3
    """Random environments per team evaluation."""
    ticks: int | None = None
    """Episode length in ticks; None: the scenario's."""
    seed: int = 0
    """Seed of the run's random generator."""
    device: str = "auto"
    """'auto', 'cpu' or 'cuda'."""
    compile: bool | None = None
    """torch.compile the tick; None: on CUDA, and on CPU for runs of >= 50 generations."""
    tag_length: int = 16
    """Bits in the speciation / partner tag."""
    bt_length: int = 32
    """Slots in a behavior-tree program."""
    delta: float = 0.4
    """Speciation threshold."""
    p_marginal: float = 0.25
    """Fitness factor when the marginal contribution is not positive."""
    alpha: float = 0.6
    """EMA decay of fitness (weight of the previous value)."""
    lam: float = 0.001
    """Budget penalty decay."""
    max_elite: int = 3
    """E in the elite count N = max(1, min(E, floor(size/5) + 1))."""
    dominance: bool = True
    """Sample team slots by the dominance genes; False: uniformly (an ablation)."""
    quota_basis: str = "sum"
    """Offspring quotas proportional to each species' total ('sum') or mean ('mean') fitness."""
    min_share: float = 1.0
    """A species whose quota share is below this many individuals gets no slot (0: none)."""
    hw_sigma: float = 0.05
    """Mutation: Gaussian step of radius and operating points, as a fraction of their range."""
    social_sigma: float = 0.05
    """Mutation: Gaussian step of selectivity and dominance."""
    p_categorical: float = 0.02
    """Mutation: probability of resampling each tier and the effector."""
    p_tag_flip: float = 0.01
    """Mutation: probability of flipping each tag bit."""
    d_hw_tiers: bool = False
    """d_hw also over the three hardware tiers (true: the behaviour before 0.2; the paper's d_hw is
    over the continuous hardware genes only)."""
    bt_point_on_nodes: bool = True
    """A behavior-tree point mutation re-draws one of the tree's nodes, never the NOP padding
    (false: any slot, the behaviour before 0.2)."""
    bt_mutation_rate: float = 0.5
    """Mutation: probability that an offspring gets its behavior-tree mutation event (1.0: every
    offspring, the behaviour before 0.2)."""
    p_gene_mutation: float = 0.2
    """Mutation: probability that each continuous gene (radius, operating points, selectivity,
    dominance) of an offspring gets its Gaussian step (1.0: every gene, the behaviour before
    0.2). With every gene stepped in every child, a species' members spread so far from its
    prototype that any categorical change founds a species (docs/RESULTS.md)."""
    merge_species: bool = False
    """Dissolve a species whose prototype comes within delta of an older one's (not in the paper;
    an experiment)."""
    evaluated_partners: bool = False
    """Partners are species elites that have a fitness: a species founded this generation is no
    one's partner (an experiment, off by default: it did not reduce the species in best teams)."""
    cuda_graphs: bool | None = None
    """Replay the compiled tick as CUDA graphs of 10 ticks (`world.CudaGraphTicks`). Unset: on
    wherever the tick runs compiled on CUDA; true on the CPU or with the eager tick is an error."""

    def validate(self, option_names: dict[str, str] | None = None, memory: bool = True) -> None:
        """Raise ValueError with a one-line message for an invalid setting: a value of the wrong
        type, out of its range, NaN or infinite where a finite number is meant, or (`memory`)
        sizes whose evaluation cannot fit in this machine's memory (`runs.check_memory`; off
        for a config read back only to be looked at). The message names the setting as the
        command line spells it (--population, --set delta; `option_names` maps keys to other
        spellings, e.g. {"seed": "--seeds"} in a sweep)."""
        names = {k: "--" + k.replace("_", "-") for k in OPTION_KEYS}
        names.update(option_names or {})

        def name(key: str) -> str:
            return names.get(key, f"--set {key}")

        kinds = {"bool": (bool,), "int": (int,), "float": (int, float), "str": (str,)}
        for f in fields(self):
            v = getattr(self, f.name)
            base, _, rest = str(f.type).partition(" | ")
            if v is None:
                if rest != "None":
                    raise ValueError(f"{name(f.name)} must be set")
                continue
            if not isinstance(v, kinds[base]) or (isinstance(v, bool) and base != "bool"):
                what = {"bool": "true or false", "int": "an integer", "float": "a number",
                        "str": "a string"}[base]
                raise ValueError(f"{name(f.name)} must be {what}, got {v!r}")
        if self.budget is not None:
            if not math.isfinite(self.budget):
                raise ValueError(f"{name('budget')} must be a finite number, got {self.budget}")
            if self.budget <= 0:
                raise ValueError(f"{name('budget')} must be > 0, got {self.budget:g}")
        if not self.scenario:
            raise ValueError(f"{name('scenario')} must name a scenario")
        if self.quota_basis not in ("sum", "mean"):
            raise ValueError(f"{name('quota_basis')} must be 'sum' or 'mean', "
                             f"got {self.quota_basis!r}")
        if self.objective not in ("fitness", "roi"):
            raise ValueError(f"{name('objective')} must be 'fitness' or 'roi', "
                             f"got {self.objective!r}")
        dev = self.device
        if dev not in ("auto", "cpu", "cuda") and not (
                dev.startswith("cuda:") and dev[5:].isdigit() and dev[5:].isascii()):
            raise ValueError(f"{name('device')} must be auto, cpu, cuda or cuda:N, got {dev!r}")
        # lower bounds; the sizes' upper bound is the memory their evaluation needs
        for key, lo in (("generations", 1), ("population", 2), ("trials", 1), ("tag_length", 1),
                        ("bt_length", 4), ("max_elite", 1), ("swarm_size", 1), ("ticks", 1),
                        ("seed", 0)):
            v = getattr(self, key)
            if v is not None and v < lo:
                raise ValueError(f"{name(key)} must be >= {lo}, got {v}")
        if self.seed > MAX_SEED:
            raise ValueError(f"{name('seed')} must be in [0, {MAX_SEED}] (2**63 - 1), "
                             f"got {self.seed}")
        for key in ("delta", "lam", "hw_sigma", "social_sigma", "min_share"):
            v = getattr(self, key)
            if not (v >= 0 and math.isfinite(v)):          # also refuses nan
                raise ValueError(f"{name(key)} must be a finite number >= 0, got {v}")
        if not self.delta > 0:
            raise ValueError(f"{name('delta')} must be a finite number > 0, got {self.delta}")
        for key in ("p_marginal", "alpha", "p_categorical", "p_tag_flip", "bt_mutation_rate",
                    "p_gene_mutation"):
            v = getattr(self, key)
            if not (v >= 0 and math.isfinite(v)):
                raise ValueError(f"{name(key)} must be a finite number in [0, 1], got {v}")
            if v > 1:
                raise ValueError(f"{name(key)} must be <= 1 (a number in [0, 1]), got {v}")
        if memory:
            from .runs import check_memory          # runs imports this module

            check_memory(self, option_names=names)
        for key, hi in UPPER_BOUNDS.items():
            v = getattr(self, key)
            if v is not None and v > hi:
                fmt = "g" if isinstance(hi, float) else "d"
                raise ValueError(f"{name(key)} must be <= {hi:{fmt}}, got {v:{fmt}}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "EvolveConfig":
        if not isinstance(d, dict):
            raise ValueError(f"expected a table of config keys, got {type(d).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown config keys: {', '.join(unknown)}")
        for k, v in d.items():
            if v is not None and not isinstance(v, (bool, int, float, str)):
                raise ValueError(f"{k}: expected a single value, got {v!r}")
        d = {k: (None if v == "none" else v) for k, v in d.items()}
        if "quota_basis" not in d:
            # written before these settings existed: keep the run's original algorithm
            d = {**LEGACY_DEFAULTS, **d}
        if "p_tag_flip" not in d:
            # written before the tag flip rate was a setting: it was one bit in L per child
            d["p_tag_flip"] = 1.0 / int(d.get("tag_length", cls.tag_length))
        if "min_share" not in d:
            d["min_share"] = 0.0     # written before the quota threshold existed
        # written before the paper-text fixes of d_hw and the tree mutation: the old behaviour
        d.setdefault("d_hw_tiers", True)
        d.setdefault("bt_point_on_nodes", False)
        d.setdefault("bt_mutation_rate", 1.0)
        d.setdefault("p_gene_mutation", 1.0)
        if d.get("ticks") is None and d.get("scenario") in LEGACY_EPISODE_TICKS:
            # written before runs pinned their episode length: the scenario's length of that time
            d["ticks"] = LEGACY_EPISODE_TICKS[d["scenario"]]
        return cls(**d)


#: The largest seed a run's generator takes (torch.Generator.manual_seed accepts 64 bits; a seed
#: is kept non-negative and below 2**63 so that it reads back the same everywhere).
MAX_SEED = 2 ** 63 - 1

#: Upper bounds of settings that memory does not bound (checked after `runs.check_memory`, so
#: that sizes far too large for memory are told what they would need).
UPPER_BOUNDS = {"generations": 10_000_000, "ticks": 1_000_000, "tag_length": 4096,
                "bt_length": 4096, "max_elite": 1_000_000, "population": 100_000_000,
                "trials": 1_000_000, "swarm_size": 10_000_000,
                # numbers the float32 tensors must hold with room to spare (delta=1e300 is inf
                # there; social_sigma=1e300 makes NaN genes)
                "budget": 1e15, "delta": 1e6, "lam": 1e6, "hw_sigma": 1e6,
                "social_sigma": 1e6, "min_share": 1e9}


#: Settings of configs saved before `quota_basis` and the mutation steps were config keys.
LEGACY_DEFAULTS = {"quota_basis": "mean", "hw_sigma": 0.1, "social_sigma": 0.1,
                   "p_categorical": 0.1}


#: Episode lengths of built-in scenarios whose default has changed since runs began pinning
#: theirs in config.toml; a saved config without `ticks` ran with these.
LEGACY_EPISODE_TICKS = {"one-niche": 250, "two-niche": 250, "four-niche": 250}


def resolve_device(name: str) -> torch.device:
    """The torch device for 'auto' / 'cpu' / 'cuda[:i]'; ValueError when CUDA is missing."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise ValueError("--device cuda was asked for, but no CUDA device is available")
    try:
        dev = torch.device(name)
    except RuntimeError:
        raise ValueError(f"--device must be auto, cpu, cuda or cuda:N, got {name!r}") from None
    if dev.type == "cuda" and dev.index is not None and dev.index >= torch.cuda.device_count():
        raise ValueError(f"--device {name}: there are only {torch.cuda.device_count()} CUDA "
                         "devices")
    return dev


# ------------------------------------------------------------------ the population
def random_population(n: int, cfg: EvolveConfig, generator: torch.Generator,
                      device: torch.device) -> Genome:
    """The initial population: random genes, each seeded with a randomised template tree."""
    g = generator

    def u(*shape):
        return torch.rand(*shape, generator=g, device=device)

    names = list(bt.TEMPLATES)
    templates = torch.stack([bt.template_tensor(k, cfg.bt_length) for k in names]).to(device)
    which = torch.randint(0, len(names), (n,), generator=g, device=device)
    programs = mutate_bt(templates[which], reproduction_params(cfg), g)
    tiers = lambda: torch.randint(0, NUM_TIERS, (n,), generator=g, device=device)  # noqa: E731
    return Genome(
        tag=u(n, cfg.tag_length) < 0.5, selectivity=u(n), dominance=u(n), bt=programs,
        radius=R_MIN + (R_MAX - R_MIN) * u(n), chassis=tiers(), battery=tiers(), motor=tiers(),
        torque_point=u(n), battery_point=u(n),
        effector=torch.randint(0, 2, (n,), generator=g, device=device))


@dataclass
class EvolutionState:
    """Everything needed to continue a run after `generation` completed generations."""

    generation: int
    genome: Genome                 # the population to be evaluated next
    species_hint: Tensor           # [P] species inherited from the parent (-1: none)
    proto: Genome | None           # previous generation's species prototypes
    proto_ids: Tensor              # [K] their species ids
    next_species_id: int
    fitness: Tensor                # [P] smoothed fitness carried by elites
    has_fitness: Tensor            # [P] bool
    rng_state: Tensor              # the run generator's state
    best: dict | None = None       # best team of the run so far
    history: list = field(default_factory=list)  # per-generation composition records
    turnover: Turnover = field(default_factory=Turnover)  # species births and deaths (derived
    #                                                       from history; not saved)


@dataclass
class Context:
    """Run constants derived from the config (not saved; rebuilt on resume)."""

    cfg: EvolveConfig
    scenario: Scenario
    device: torch.device
    eval_cfg: EvalConfig
    repro: ReproductionParams
    params: WorldParams
    step_fn: Any
    compiled: bool = False
    weights: DistanceWeights = DistanceWeights()
    evaluator: Any = None
    """Where evaluations are simulated: None, in this process; else an object whose
    `simulate(plan, genome)` returns their per-environment metrics (`evaluation.evaluate`;
    `distributed.ShardedEvaluator` shards them over Ray actors)."""

    @property
    def tick_mode(self) -> str:
        """How the world tick runs: 'eager', 'compiled', 'compiled, CUDA graphs', or 'eager
        (compiling failed)' once a compiled tick has fallen back."""
        fn = self.step_fn
        graphs = isinstance(fn, CudaGraphTicks)
        compiled_step = fn.step_fn if graphs else fn
        if isinstance(compiled_step, CompiledStep) and compiled_step.error is not None:
            return "eager (compiling failed)"
        if graphs:
            return "compiled, CUDA graphs"
        return "compiled" if self.compiled else "eager"


def reproduction_params(cfg: EvolveConfig) -> ReproductionParams:
    """The reproduction settings of a run."""
    return ReproductionParams(delta=cfg.delta, max_elite=cfg.max_elite,
                              quota_basis=cfg.quota_basis, min_share=cfg.min_share,
                              hw_sigma=cfg.hw_sigma, social_sigma=cfg.social_sigma,
                              p_categorical=cfg.p_categorical, p_tag_flip=cfg.p_tag_flip,
                              bt_point_on_nodes=cfg.bt_point_on_nodes,
                              bt_mutation_rate=cfg.bt_mutation_rate,
                              p_gene_mutation=cfg.p_gene_mutation)


def make_context(cfg: EvolveConfig) -> Context:
    """Validate the config, load the scenario and pick the device and tick function."""
    cfg.validate()
    scenario = load_scenario(cfg.scenario)
    device = resolve_device(cfg.device)
    S = cfg.swarm_size or scenario.num_robots
    eval_cfg = EvalConfig(swarm_size=S, trials=cfg.trials, ticks=cfg.ticks or scenario.episode_ticks,
                          budget=cfg.budget, objective=cfg.objective, lam=cfg.lam,
                          p_marginal=cfg.p_marginal, max_elite=cfg.max_elite,
                          dominance=cfg.dominance, evaluated_partners=cfg.evaluated_partners,
                          weights=FitnessWeights())
    repro = reproduction_params(cfg)
    use_compile = cfg.compile if cfg.compile is not None else (
        device.type == "cuda" or cfg.generations >= COMPILE_MIN_GENERATIONS)
    if cfg.cuda_graphs and (device.type != "cuda" or not use_compile):
        raise ValueError("cuda_graphs needs --device cuda and the compiled tick (--compile)")
    step_fn = CompiledStep() if use_compile else world_step
    graphs = cfg.cuda_graphs if cfg.cuda_graphs is not None else (
        device.type == "cuda" and use_compile)
    if graphs:  # unset (auto): a tick that fails to compile runs eagerly, as without graphs
        step_fn = CudaGraphTicks(step_fn, required=cfg.cuda_graphs is not None)
    # pin the scenario's team size and episode length into the config, so that a saved run keeps
    # them if a built-in scenario's defaults change later
    cfg = replace(cfg, swarm_size=S, ticks=eval_cfg.ticks)
    return Context(cfg, scenario, device, eval_cfg, repro, WorldParams.for_scenario(scenario),
                   step_fn, use_compile, DistanceWeights(hw_tiers=cfg.d_hw_tiers))


def new_generator(ctx: Context) -> torch.Generator:
    return torch.Generator(device=ctx.device).manual_seed(ctx.cfg.seed)


def init_state(ctx: Context) -> EvolutionState:
    """Generation 0: a random population, no species yet."""
    g = new_generator(ctx)
    P = ctx.cfg.population
    genome = random_population(P, ctx.cfg, g, ctx.device)
    return EvolutionState(
        generation=0, genome=genome,
        species_hint=torch.full((P,), -1, dtype=torch.long, device=ctx.device),
        proto=None, proto_ids=torch.zeros(0, dtype=torch.long, device=ctx.device),
        next_species_id=0, fitness=torch.zeros(P, device=ctx.device),
        has_fitness=torch.zeros(P, dtype=torch.bool, device=ctx.device),
        rng_state=g.get_state())


def _design(genome: Genome, row: int, species: int, cost: float) -> dict:
    """A JSON-friendly description of one robot design."""
    return {
        "species": species, "effector": "pincher" if int(genome.effector[row]) else "suction",
        "radius": round(float(genome.radius[row]), 4),
        "chassis_tier": int(genome.chassis[row]) + 1, "battery_tier": int(genome.battery[row]) + 1,
        "motor_tier": int(genome.motor[row]) + 1,
        "torque_point": round(float(genome.torque_point[row]), 4),
        "battery_point": round(float(genome.battery_point[row]), 4),
        "dominance": round(float(genome.dominance[row]), 4),
        "selectivity": round(float(genome.selectivity[row]), 4),
        "cost": round(cost, 2), "bt": [int(x) for x in genome.bt[row].tolist()],
    }


def generation(state: EvolutionState, ctx: Context) -> tuple[EvolutionState, dict]:
    """Advance one generation; the new state and this generation's metrics."""
    t0 = time.perf_counter()
    cfg = ctx.cfg
    g = torch.Generator(device=ctx.device)
    g.set_state(state.rng_state)
    genome = state.genome

    # 1. dynamic speciation
    sp = speciate(genome, state.species_hint, state.proto, state.proto_ids,
                  state.next_species_id, cfg.delta, w=ctx.weights, merge=cfg.merge_species)

    # 2. evaluation of every individual, all teams and trials in one batch
    t_eval = time.perf_counter()
    res = evaluate(genome, sp.species, sp.proto_ids, sp.proto_index, state.fitness,
                   state.has_fitness, ctx.scenario, ctx.eval_cfg, g, ctx.params, ctx.step_fn,
                   evaluator=ctx.evaluator)
    eval_seconds = time.perf_counter() - t_eval
    fit = ema(state.fitness, res.fitness, state.has_fitness, cfg.alpha)

    # the best team of this generation: the team of the individual with the highest fitness
    # score (gated: a focal whose marginal contribution is not positive is penalised, so a strong
    # team carried by its partners is not credited to a focal that weakens it)
    b = int(res.fitness.argmax())
    team = res.swarms.focal_team[b]
    rows, counts = torch.unique(team[team >= 0], return_counts=True)
    cost = genome_phenotype(genome).cost
    # to the host in one transfer per field, not one per value (each is a device sync)
    host = genome.index(rows).to("cpu")
    can = capabilities(genome_phenotype(host), ctx.scenario, ctx.params).tolist()  # [R][C]
    designs = [dict(_design(host, i, s, c), count=n,
                    capability=[j for j, ok in enumerate(can[i]) if ok])
               for i, (s, c, n) in enumerate(zip(sp.species[rows].tolist(), cost[rows].tolist(),
                                                 counts.tolist()))]
    designs.sort(key=lambda d: -d["count"])
    tm = dict(zip(res.team_metrics, torch.stack([v[b].float() for v in res.team_metrics.values()])
                  .tolist()))
    team_record = {
        "generation": state.generation, "fitness": float(res.focal[b]),
        "cost": float(res.team_cost[b]), "species": len(designs),
        "niches": niche_count(d["capability"] for d in designs),
        "deliveries_individual": tm["delivered_individual"],
        "deliveries_collab": tm["delivered_collab"],
        "deliveries": tm["delivered_individual"] + tm["delivered_collab"],
        "energy_used": tm["energy_used"], "designs": designs,
    }
    best = state.best
    if best is None or team_record["fitness"] > best["fitness"]:
        best = team_record

    ids, sizes = torch.unique(sp.species, return_counts=True)
    composition = {
        "generation": state.generation,
        "population": {int(i): int(n) for i, n in zip(ids.tolist(), sizes.tolist())},
        "team": {str(d["species"]): d["count"] for d in designs},
    }
    turnover = state.turnover.copy()
    founded, extinct = turnover.advance(state.generation, composition["population"])

    # 3. reproduction
    children, hint, is_elite, parent = reproduce(genome, fit, sp.species, sp.proto_index,
                                                 sp.proto_ids, ctx.repro, g,
                                                 partial(distance, w=ctx.weights))
    new_state = EvolutionState(
        generation=state.generation + 1, genome=children, species_hint=hint,
        proto=genome.index(sp.proto_index), proto_ids=sp.proto_ids,
        next_species_id=sp.next_species_id,
        fitness=torch.where(is_elite, fit[parent], 0.0), has_fitness=is_elite,
        rng_state=g.get_state(), best=best, history=state.history + [composition],
        turnover=turnover)

    budget = cfg.budget if cfg.budget is not None else float("nan")
    metrics = {
        "generation": state.generation,
        "fitness/best": float(fit.max()), "fitness/mean": float(fit.mean()),
        "species/count": int(ids.numel()),
        "species/founded": founded, "species/extinct": extinct,
        "species/median_age": median(turnover.ages(state.generation, composition["population"])),
        "team/fitness": team_record["fitness"], "team/species": team_record["species"],
        "team/niches": team_record["niches"],
        "team/median_age": median(turnover.ages(state.generation, composition["team"])),
        "team/focal_max": float(res.focal.max()),
        "team/cost": team_record["cost"], "team/budget": budget,
        "team/deliveries": team_record["deliveries"],
        "team/deliveries_individual": team_record["deliveries_individual"],
        "team/deliveries_collab": team_record["deliveries_collab"],
        "team/energy_used": team_record["energy_used"],
        "perf/generation_seconds": time.perf_counter() - t0,
        "perf/eval_seconds": eval_seconds,
        "perf/sim_seconds": res.sim_seconds,
        # non-scalars, for reporters
        "team": team_record, "team/rows": team, "best": best, "composition": composition,
        "hist/radius": genome.radius.detach().cpu(),
        "hist/dominance": genome.dominance.detach().cpu(),
        "hist/selectivity": genome.selectivity.detach().cpu(),
    }
    return new_state, metrics


# ------------------------------------------------------------------ checkpoints
def state_dict(state: EvolutionState, cfg: EvolveConfig) -> dict:
    """A CPU, torch.save-able snapshot of the run."""
    return {
        "version": CHECKPOINT_VERSION, "config": cfg.to_dict(), "generation": state.generation,
        "genome": state.genome.state_dict(), "species_hint": state.species_hint.cpu(),
        "proto": state.proto.state_dict() if state.proto is not None else None,
        "proto_ids": state.proto_ids.cpu(), "next_species_id": state.next_species_id,
        "fitness": state.fitness.cpu(), "has_fitness": state.has_fitness.cpu(),
        "rng_state": state.rng_state.cpu(), "best": state.best, "history": state.history,
    }


def load_state_dict(d: dict, ctx: Context) -> EvolutionState:
    """Rebuild a state from `state_dict` output; ValueError if it does not fit this run."""
    if not isinstance(d, dict) or d.get("version") != CHECKPOINT_VERSION:
        raise ValueError("checkpoint has an unknown format or version")
    dev = ctx.device
    genome = Genome.from_state_dict(d["genome"]).to(dev)
    if genome.size != ctx.cfg.population or genome.bt.shape[1] != ctx.cfg.bt_length \
            or genome.tag.shape[1] != ctx.cfg.tag_length:
        raise ValueError("checkpoint does not match the run's population, tag or tree length")
    rng = d["rng_state"]
    if rng.numel() != torch.Generator(device=dev).get_state().numel():
        raise ValueError(f"checkpoint was written on another kind of device than {dev.type}; "
                         "resume it with the --device it was run on")
    return EvolutionState(
        generation=int(d["generation"]), genome=genome, species_hint=d["species_hint"].to(dev),
        proto=Genome.from_state_dict(d["proto"]).to(dev) if d["proto"] is not None else None,
        proto_ids=d["proto_ids"].to(dev), next_species_id=int(d["next_species_id"]),
        fitness=d["fitness"].to(dev), has_fitness=d["has_fitness"].to(dev), rng_state=rng,
        best=d["best"], history=list(d["history"]), turnover=replay(d["history"])[0])


class Evolution:
    """A run: config, context and current state; `step()` runs one generation."""

    def __init__(self, cfg: EvolveConfig, state: EvolutionState | None = None):
        self.ctx = make_context(cfg)
        self.cfg = self.ctx.cfg
        self.state = state if state is not None else init_state(self.ctx)

    @classmethod
    def from_checkpoint(cls, d: dict, cfg: EvolveConfig) -> "Evolution":
        ev = cls.__new__(cls)
        ev.ctx = make_context(cfg)
        ev.cfg = ev.ctx.cfg
        ev.state = load_state_dict(d, ev.ctx)
        return ev

    @property
    def done(self) -> bool:
        return self.state.generation >= self.cfg.generations

    def step(self) -> dict:
        self.state, metrics = generation(self.state, self.ctx)
        return metrics

    def state_dict(self) -> dict:
        return state_dict(self.state, self.cfg)


#: Config keys that `parse_settings` refuses because the command line has an option for them.
OPTION_KEYS = frozenset({"scenario", "budget", "objective", "generations", "population",
                         "swarm_size", "trials", "ticks", "seed", "device", "compile"})


def parse_settings(pairs: list[str], option_names: dict[str, str] | None = None) -> dict[str, Any]:
    """["key=value", ...] -> {key: typed value} for the algorithm's config keys (e.g. delta=0.5,
    p_tag_flip=0.0625, quota_basis=mean); ValueError with a one-line message for a malformed
    pair, an unknown key, a key that has its own option (named `option_names[key]`, default
    --key), or a value of the wrong type."""
    kinds = {f.name: f.type for f in fields(EvolveConfig)}
    out: dict[str, Any] = {}
    for pair in pairs:
        key, sep, text = pair.partition("=")
        key, text = key.strip().replace("-", "_"), text.strip()
        if not sep or not key or not text:
            raise ValueError(f"--set expects KEY=VALUE, got {pair!r}")
        if key in out:
            raise ValueError(f"--set {key} is given twice")
        if key in OPTION_KEYS:
            option = (option_names or {}).get(key, "--" + key.replace("_", "-"))
            raise ValueError(f"--set {key}: use the {option} option")
        if key not in kinds:
            settable = ", ".join(sorted(set(kinds) - OPTION_KEYS))
            raise ValueError(f"--set: unknown key {key!r} (settable: {settable})")
        kind = kinds[key]
        try:
            if kind in ("bool", "bool | None"):
                if text.lower() not in ("true", "false"):
                    raise ValueError
                out[key] = text.lower() == "true"
            elif kind == "int":
                out[key] = int(text)
            elif kind == "float":
                out[key] = float(text)
            else:
                out[key] = text
        except ValueError:
            raise ValueError(f"--set {key}: expected a value of type "
                             f"{kind.removesuffix(' | None')}, got {text!r}") from None
    return out


def with_overrides(cfg: EvolveConfig, **kw) -> EvolveConfig:
    """A copy of cfg with the given fields replaced (None values are ignored)."""
    return replace(cfg, **{k: v for k, v in kw.items() if v is not None})
