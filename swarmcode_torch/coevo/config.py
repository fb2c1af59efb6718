"""The settings of a SwarmCoDe run, each with its one default and its range.

`SwarmCoDeConfig` is what a run is (config.toml holds its fields, flat). The algorithm reads it
through three parts built from it by field name, never by a hand-written copy:

    cfg.evaluation(num_robots, episode_ticks) -> EvalConfig   how teams are built and scored
    cfg.speciation                            -> SpeciationParams
    cfg.reproduction                          -> ReproductionParams

A part's setting that is also a run setting takes the run's default (`SwarmCoDeConfig.delta`
and so on), so `ReproductionParams()` in a notebook is the algorithm a default run uses.
Migrations of configs written by older versions are the application's (`app.runs`).
"""

from __future__ import annotations

import math
import typing
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

@dataclass(frozen=True)
class SwarmCoDeConfig:
    """Everything that defines a run (saved as config.toml in the run directory): each setting
    and its default, once. The algorithm reads it through its parts: `evaluation`,
    `speciation` and `reproduction`, built from these fields by name."""

    preset: str | None = "default"
    """The preset the run's algorithm settings started from (`PRESETS`): "default" or "paper";
    none: written before presets existed (0.6). Settings given on top of it are recorded
    beside it."""
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
    gate_margin: float = 0.0
    """The gate penalises a focal whose marginal contribution is at most -gate_margin times its
    baseline's score (0: every contribution that is not positive, the paper's gate). An
    experiment beyond the paper: a focal that is about as good as the robots that replace it is
    not penalised, so two species of one niche need not gate each other (docs/RESULTS.md)."""
    alpha: float = 0.6
    """EMA decay of fitness (weight of the previous value)."""
    lam: float = 0.001
    """Budget penalty decay."""
    max_elite: int = 3
    """The cap of a species' elite count max(1, min(max_elite, floor(size / 5) + 1)) (the paper's E)."""
    dominance: bool = True
    """Sample team slots by the dominance genes; False: uniformly (an ablation)."""
    quota_basis: str = "sum"
    """Where `quota_size_exponent` is unset: offspring quotas proportional to each species'
    total ('sum', the paper's) or mean ('mean') fitness, or to the mean times the square root
    of the species' size ('sqrt', an experiment between the two: a species' size then settles
    where it is proportional to its mean fitness squared)."""
    quota_size_exponent: float | None = 0.75
    """Each species' quota is proportional to its mean fitness times its size to this power (1:
    the paper's total, 'sum'; 0: 'mean'; 0.5: 'sqrt'); a species' size then settles, for an
    exponent below 1, where it is proportional to its mean fitness to the power
    1 / (1 - exponent). Unset (none): quotas as `quota_basis` says. 0.75 since 0.4, with
    `partners_per_niche = "one"`; beyond the paper (docs/MODEL.md, docs/RESULTS.md)."""
    quota_inertia: float = 0.0
    """A species' quota share moves this fraction of the way from its share of the fitness
    back toward its present size (0: the share of the fitness, the paper's quota; 0.5:
    neat-python's spawn step, half-way from the previous size to the target). An experiment
    beyond the paper (docs/RESULTS.md)."""
    min_share: float = 1.0
    """A species whose quota share is below this many individuals gets no slot (0: none)."""
    hw_sigma: float = 0.05
    """Mutation: Gaussian step of radius and operating points, as a fraction of their range."""
    social_sigma: float = 0.05
    """Mutation: Gaussian step of selectivity and dominance."""
    p_categorical: float = 0.02
    """Mutation: probability of resampling each tier and the effector."""
    p_effector: float | None = 0.005
    """Mutation: probability of resampling the effector (None: p_categorical, as the tiers; the
    behaviour before 0.5). 0.005 since 0.5, beyond the paper: after generation 100 nearly every
    species founded is an effector flip that dies at once, and with one partner per niche a
    niche no longer needs flips to be founded again (docs/RESULTS.md)."""
    effector_flip: str = "gene"
    """How an offspring's effector changes: 'gene', resampled like any categorical gene of the
    child; 'prototype' (an experiment beyond the paper), a flip is its own event that replaces
    the child by a copy of its species' prototype with the other effector, so that it lies
    exactly w_tool < delta from that prototype and joins the species instead of founding one."""
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
    partners_per_niche: str = "all"
    """Which species may be partners: "all" (the paper: any species whose tag the focal's
    selectivity accepts) or "one", a diagnostic reference that is no part of SwarmCoDe: of the
    species whose elites have the same capability (the scenario's package classes a design can
    lift), only the largest may be a partner. "one" tells the algorithm the task's niches; it
    was the default of 0.4 and 0.5 and is kept so that their runs can be compared and resumed."""
    baseline_refill: str = "any"
    """Where a focal's slots in its baseline team are re-filled from: "any" partner in its team
    by dominance (the paper); "nearest", all from the partner species in its team whose
    prototype's robot is the nearest design to its own species' prototype (the hardware terms
    of D: operating points, effector, size), so that the baseline asks whether the most similar
    robots among its partners can do the focal's job; or "senior", only
    species larger than the focal's own (as large: older), the slots staying empty where there
    is none (a candidate of 0.6 that was not adopted; docs/RESULTS.md)."""
    partner_admission: str = "substitute"
    """When a species becomes and stays a partner (`coevo.admission`): "open", from its founding
    (the paper); "substitute", every focal's baseline re-fills its slots from its nearest
    partner design, a species founded after generation 0 is no one's partner until its members
    are seldom gated (its robots do what that partner's cannot), and a partner gated half the
    time or more is a substitute of its nearest partner, the lower-ranked of the two (smaller,
    then younger) stopping being a partner; "gate", probation and demotion as "substitute" but
    with the paper's baseline and two mostly gated partners demoting the lowest-ranked (a
    candidate of 0.6, not adopted). Beyond the paper and scenario-agnostic: it reads genomes,
    species sizes and ages, and the gate's results (docs/RESULTS.md)."""
    cuda_graphs: bool | None = None
    """Replay the compiled tick as CUDA graphs of 10 ticks (`sim.runtime.CudaGraphTicks`). Unset: on
    wherever the tick runs compiled on CUDA; true on the CPU or with the eager tick is an error."""
    fitness_function: str | None = None
    """None: teams are scored by the built-in fitness (`evaluation.team_scores`); else the name
    of the user function that scored them ("module.qualname"; a function is given to the API,
    `swarmcode_torch.evolve(fitness=fn)`, and again to `resume`: a config records its name only)."""
    # the raw-fitness weights of the paper's Table IV (`fitness.raw_fitness`, `FitnessWeights`)
    w_delivery: float = 100.0
    """Raw fitness: points per package delivered (and per grip of a delivered collaborative one)."""
    w_collab_bonus: float = 50.0
    """Raw fitness: bonus points per collaborative package delivered."""
    w_pickup: float = 1.0
    """Raw fitness: points per package picked up."""
    w_energy: float = 0.03
    """Raw fitness: points per unit of mean final battery energy."""
    w_proximity: float = 1.0
    """Raw fitness: weight of the proximity term (robots near packages)."""
    w_closeness: float = 30.0
    """Raw fitness: weight of the closeness term (packages brought near the base)."""
    inactive_factor: float = 0.5
    """Raw fitness: factor (P_activity, in [0, 1]) on a team's score when it picked up nothing."""
    fitness_floor: float = 0.1
    """Raw fitness: the lowest raw fitness a team-episode gets."""

    def validate(self, option_names: dict[str, str] | None = None, bounds: bool = True) -> None:
        """Raise ValueError with a one-line message for an invalid setting: a value of the wrong
        type, out of its range, NaN or infinite where a finite number is meant. The message
        names the setting by its key, or as `option_names[key]` spells it (the command line
        passes its flags: --population, --set delta). `bounds=False` leaves out the upper
        bounds (`check_bounds`), so that the application can first tell a run far too large
        for memory what it would need (`app.runs.check_config`)."""
        names = option_names or {}

        def name(key: str) -> str:
            return names.get(key, key)

        for f in fields(self):
            v = getattr(self, f.name)
            kind, optional = SETTING_TYPES[f.name]
            if v is None:
                if not optional:
                    raise ValueError(f"{name(f.name)} must be set")
                continue
            if not isinstance(v, _ACCEPTS[kind]) or (isinstance(v, bool) and kind is not bool):
                raise ValueError(f"{name(f.name)} must be {_KIND_TEXT[kind]}, got {v!r}")
        if self.budget is not None:
            if not math.isfinite(self.budget):
                raise ValueError(f"{name('budget')} must be a finite number, got {self.budget}")
            if self.budget <= 0:
                raise ValueError(f"{name('budget')} must be > 0, got {self.budget:g}")
        if not self.scenario:
            raise ValueError(f"{name('scenario')} must name a scenario")
        if self.fitness_function is not None and not self.fitness_function.strip():
            raise ValueError(f"{name('fitness_function')} must name a function or be unset")
        for key, opts in CHOICES.items():
            v = getattr(self, key)
            if v not in opts:
                one_of = ", ".join(map(repr, opts[:-1])) + f" or {opts[-1]!r}"
                raise ValueError(f"{name(key)} must be {one_of}, got {v!r}")
        if self.quota_basis != "sum" and self.quota_size_exponent is not None:
            raise ValueError(f"{name('quota_basis')}={self.quota_basis} takes effect only with "
                             f"quota_size_exponent unset (it is {self.quota_size_exponent:g}, "
                             f"which sets the quotas): give quota_size_exponent=none as well")
        for key, opts in OPTIONAL_CHOICES.items():
            v = getattr(self, key)
            if v is not None and v not in opts:
                raise ValueError(f"{name(key)} must be {' or '.join(map(repr, opts))} or unset, "
                                 f"got {v!r}")
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
        for key in ("w_delivery", "w_collab_bonus", "w_pickup", "w_energy", "w_proximity",
                    "w_closeness", "fitness_floor"):
            v = getattr(self, key)
            if not (v >= 0 and math.isfinite(v)):
                raise ValueError(f"{name(key)} must be a finite number >= 0, got {v}")
        for key in ("p_marginal", "gate_margin", "quota_inertia", "quota_size_exponent",
                    "alpha", "p_categorical", "p_effector", "p_tag_flip",
                    "bt_mutation_rate", "p_gene_mutation", "inactive_factor"):
            v = getattr(self, key)
            if v is None:                  # an optional one left unset (`p_effector`)
                continue
            if not (v >= 0 and math.isfinite(v)):
                raise ValueError(f"{name(key)} must be a finite number in [0, 1], got {v}")
            if v > 1:
                raise ValueError(f"{name(key)} must be <= 1 (a number in [0, 1]), got {v}")
        if bounds:
            self.check_bounds(option_names)

    def check_bounds(self, option_names: dict[str, str] | None = None) -> None:
        """ValueError for a setting above its upper bound (`UPPER_BOUNDS`)."""
        names = option_names or {}
        for key, hi in UPPER_BOUNDS.items():
            v = getattr(self, key)
            if v is not None and v > hi:
                fmt = "g" if isinstance(hi, float) else "d"
                raise ValueError(f"{names.get(key, key)} must be <= {hi:{fmt}}, got {v:{fmt}}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "SwarmCoDeConfig":
        """The config of a table of this version's keys ("none" is None); ValueError for an
        unknown key or a value that is not a single value. Not checked (`validate`); a table
        written by an older version goes through `app.runs.migrate_config` first."""
        if not isinstance(d, dict):
            raise ValueError(f"expected a table of config keys, got {type(d).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown config keys: {', '.join(unknown)}")
        for k, v in d.items():
            if v is not None and not isinstance(v, (bool, int, float, str)):
                raise ValueError(f"{k}: expected a single value, got {v!r}")
        return cls(**{k: (None if v == "none" else v) for k, v in d.items()})

    def evaluation(self, num_robots: int, episode_ticks: int) -> "EvalConfig":
        """How teams are scored, with the scenario's team size and episode length where the
        run leaves them unset."""
        return _part(EvalConfig, self, swarm_size=self.swarm_size or num_robots,
                     ticks=self.ticks or episode_ticks, weights=self.fitness_weights)

    @property
    def fitness_weights(self) -> "FitnessWeights":
        """The raw-fitness weights of the run (`w_delivery`, ..., `fitness_floor`)."""
        return FitnessWeights(**{f: float(getattr(self, key)) for f, key in FITNESS_KEYS.items()})

    @property
    def speciation(self) -> "SpeciationParams":
        return SpeciationParams(delta=self.delta, weights=DistanceWeights(hw_tiers=self.d_hw_tiers),
                                merge_species=self.merge_species)

    @property
    def reproduction(self) -> "ReproductionParams":
        return _part(ReproductionParams, self)


#: The settings that name one of a few choices (validated in `SwarmCoDeConfig.validate`).
CHOICES = {"effector_flip": ("gene", "prototype"), "quota_basis": ("sum", "mean", "sqrt"),
           "objective": ("fitness", "roi"), "partners_per_niche": ("all", "one"),
           "baseline_refill": ("any", "senior", "nearest"), "partner_admission": ("open", "gate", "substitute")}
#: Choices of settings that may also be unset.
OPTIONAL_CHOICES = {"preset": ("default", "paper")}

#: Algorithm settings of each preset, over the defaults of `SwarmCoDeConfig` ("default" is
#: those defaults). "paper": our reading of the paper's text with nothing beyond it: every
#: species the tags accept is a partner, a focal's slots are re-filled from any partner,
#: offspring quotas proportional to each species' total fitness, the effector resampled as the
#: tiers are (docs/MODEL.md, "Presets").
PRESETS: dict[str, dict[str, Any]] = {
    "default": {},
    "paper": {"partners_per_niche": "all", "baseline_refill": "any", "partner_admission": "open",
              "quota_basis": "sum",
              "quota_size_exponent": None, "p_effector": None},
}


def preset_config(name: str = "default", **settings: Any) -> "SwarmCoDeConfig":
    """The config of preset `name` (`PRESETS`) with `settings` (config keys) on top; ValueError
    naming the presets for an unknown name."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r} (presets: {', '.join(PRESETS)})")
    return replace(SwarmCoDeConfig(), **{**PRESETS[name], **settings, "preset": name})


#: The largest seed a run's generator takes (torch.Generator.manual_seed accepts 64 bits; a seed
#: is kept non-negative and below 2**63 so that it reads back the same everywhere).
MAX_SEED = 2 ** 63 - 1

#: Upper bounds of settings that memory does not bound (the application checks memory first
#: (`app.runs.check_memory`), so that sizes far too large for memory are told what they would need).
UPPER_BOUNDS = {"generations": 10_000_000, "ticks": 1_000_000, "tag_length": 4096,
                "bt_length": 4096, "max_elite": 1_000_000, "population": 100_000_000,
                "trials": 1_000_000, "swarm_size": 10_000_000,
                # numbers the float32 tensors must hold with room to spare (delta=1e300 is inf
                # there; social_sigma=1e300 makes NaN genes)
                "budget": 1e15, "delta": 1e6, "lam": 1e6, "hw_sigma": 1e6,
                "social_sigma": 1e6, "min_share": 1e9,
                # a team-episode's raw fitness is a float32 sum of these times counts
                "w_delivery": 1e12, "w_collab_bonus": 1e12, "w_pickup": 1e12, "w_energy": 1e12,
                "w_proximity": 1e12, "w_closeness": 1e12, "fitness_floor": 1e12}


EvolveConfig = SwarmCoDeConfig
"""The name of `SwarmCoDeConfig` before 0.3."""

#: SwarmCoDeConfig field -> (its type without None, whether None is allowed); from the resolved
#: annotations, not their text.
SETTING_TYPES: dict[str, tuple[type, bool]] = {}
for _name, _hint in typing.get_type_hints(SwarmCoDeConfig).items():
    _args = [a for a in typing.get_args(_hint) if a is not type(None)] or [_hint]
    SETTING_TYPES[_name] = (_args[0], type(None) in typing.get_args(_hint))
_ACCEPTS = {bool: (bool,), int: (int,), float: (int, float), str: (str,)}
_KIND_TEXT = {bool: "true or false", int: "an integer", float: "a number", str: "a string"}

_RUN = SwarmCoDeConfig          # the run defaults, as class attributes


def with_overrides(cfg: SwarmCoDeConfig, **kw) -> SwarmCoDeConfig:
    """A copy of cfg with the given fields replaced (None values are ignored)."""
    return replace(cfg, **{k: v for k, v in kw.items() if v is not None})


def _part(cls, cfg: SwarmCoDeConfig, **given):
    """An instance of part `cls` with every field that is also a run setting taken from cfg."""
    run = {f.name for f in fields(SwarmCoDeConfig)}
    shared = {f.name: getattr(cfg, f.name) for f in fields(cls) if f.name in run}
    return cls(**{**shared, **given})


# ------------------------------------------------------------------ the parts
@dataclass(frozen=True)
class FitnessWeights:
    """Weights of the raw-fitness terms (paper Table IV); `inactive_factor` is P_activity when
    no package was picked up, `floor` the minimum raw fitness. Each is a run setting
    (`FITNESS_KEYS`: W_delivery is `w_delivery`, floor is `fitness_floor`)."""

    W_delivery: float = _RUN.w_delivery
    W_collab_bonus: float = _RUN.w_collab_bonus
    W_pickup: float = _RUN.w_pickup
    W_energy: float = _RUN.w_energy
    W_proximity: float = _RUN.w_proximity
    W_closeness: float = _RUN.w_closeness
    inactive_factor: float = _RUN.inactive_factor
    floor: float = _RUN.fitness_floor


#: FitnessWeights field -> the run setting that gives it.
FITNESS_KEYS = {"W_delivery": "w_delivery", "W_collab_bonus": "w_collab_bonus",
                "W_pickup": "w_pickup", "W_energy": "w_energy", "W_proximity": "w_proximity",
                "W_closeness": "w_closeness", "inactive_factor": "inactive_factor",
                "floor": "fitness_floor"}


@dataclass(frozen=True)
class EvalConfig:
    """How teams are built and scored (`evaluation.evaluate`)."""

    swarm_size: int                 # robots per team
    ticks: int                      # episode length
    trials: int = _RUN.trials       # random environments per team (focal and baseline share them)
    budget: float | None = _RUN.budget  # $; None: no budget penalty
    objective: str = _RUN.objective  # "fitness" or "roi" (fitness divided by team cost)
    lam: float = _RUN.lam            # budget penalty decay
    p_marginal: float = _RUN.p_marginal  # factor on fitness when the marginal contribution is <= 0
    gate_margin: float = _RUN.gate_margin  # ... is <= -gate_margin * |baseline score|
    max_elite: int = _RUN.max_elite  # the elite cap (partner elites are drawn from the elites)
    dominance: bool = _RUN.dominance  # False: uniform team composition (an ablation)
    evaluated_partners: bool = _RUN.evaluated_partners  # partners are elites with a fitness
    partners_per_niche: str = _RUN.partners_per_niche  # "one": one partner species per capability
    baseline_refill: str = _RUN.baseline_refill  # "senior": re-fill a focal's slots from larger species
    weights: FitnessWeights = FitnessWeights()


@dataclass(frozen=True)
class DistanceWeights:
    """Weights of the genome distance D (paper defaults); gamma is the tag-term exponent."""

    w_tag: float = 1.0
    w_hw: float = 0.5
    w_bt: float = 0.3
    w_tool: float = 0.35
    w_size: float = 0.7
    gamma: float = 2.0
    hw_tiers: bool = _RUN.d_hw_tiers
    """d_hw also over the three tiers (run setting `d_hw_tiers`; the paper's d_hw is over the
    continuous hardware genes only)."""


@dataclass(frozen=True)
class SpeciationParams:
    """Dynamic speciation (`speciation.speciate`): the threshold, the distance and merging."""

    delta: float = _RUN.delta
    weights: DistanceWeights = DistanceWeights()
    merge_species: bool = _RUN.merge_species


@dataclass(frozen=True)
class ReproductionParams:
    """Reproduction hyperparameters (paper values where the paper gives one).

    tournament_size: individuals per tournament (with replacement; the fittest wins).
    crossover_same / crossover_cross: crossover probability when both parents are of the same /
        of different species (otherwise the child is a clone of parent 1).
    mate_tries: in-species tournaments tried for a second parent within distance `delta` of parent
        1 (and not parent 1 itself) before falling back to a global tournament (excluding parent 1).
    delta: mating compatibility threshold on the genome distance (the speciation delta).
    max_elite: the elite cap (the paper's E): a species keeps max(1, min(max_elite, size // 5 + 1)).
    quota_basis: what a species' offspring quota is proportional to: "sum", the total of its
        members' (gated, penalised, smoothed) fitness (the paper's "total adjusted fitness"), or
        "mean", NEAT's explicit fitness sharing (total / species size), or "sqrt", total /
        sqrt(species size), between the two. See docs/MODEL.md.
    quota_size_exponent: None, or quotas proportional to mean fitness x size ** exponent in
        place of `quota_basis` (1 is "sum", 0 "mean", 0.5 "sqrt").
    quota_inertia: a species' quota share is (1 - quota_inertia) x its share of the
        (sum or mean) fitness + quota_inertia x its share of the population now (0: the fitness
        share alone; 0.5: neat-python's half step from the previous size); `min_share` applies
        to that blend.
    min_share: a species whose quota share is below this many individuals gets no slot.
    bt_mutation_rate: per-offspring probability of one BT mutation event (1.0: every offspring).
    bt_subtree_prob: fraction of BT mutation events that are subtree replacements (the rest point).
    bt_point_count: slots re-drawn by one point mutation (each a uniform slot, may repeat).
    bt_point_on_nodes: a point mutation re-draws a uniform slot among the tree's nodes (its
        non-NOP slots; slot 0 of an all-NOP program), not among all slots: the NOP padding is
        not a node, so it stays padding (the paper mutates tree nodes). False: any slot.
    point_opcode_weights: weights of opcodes 0..13 for a point mutation; END and NOP at half weight
        so that structure-breaking / deleting mutations are rarer than changing a node.
    subtree_leaf_prob: probability that a replacement subtree is a single random leaf; otherwise
        it is SEQ or SEL (uniform) with 1..subtree_max_leaves (uniform) random leaves and an END.
    hw_sigma: std of the gaussian perturbation of radius, torque_point and battery_point, as a
        fraction of each gene's range; applied to a non-elite offspring's genes, clipped.
    social_sigma: the same for selectivity and dominance (range [0, 1]).
    p_categorical: per-gene probability of resampling chassis, battery, motor tier and effector
        uniformly (the new value may equal the old one).
    p_effector: the effector's resampling probability; None: p_categorical.
    effector_flip: "gene": the effector is resampled in `mutate` like the tiers; "prototype":
        `reproduce` resamples it as its own event on a copy of the species' prototype (a
        resampled value equal to the prototype's leaves the child as it was).
    p_tag_flip: per-bit tag flip probability; None means 1 / L_tag.
    p_gene_mutation: probability that each continuous gene (radius, operating points,
        selectivity, dominance) of a non-elite offspring gets its Gaussian step (1.0: every gene
        of every offspring).
    """

    tournament_size: int = 3
    crossover_same: float = 0.7
    crossover_cross: float = 0.025
    mate_tries: int = 5
    delta: float = _RUN.delta
    max_elite: int = _RUN.max_elite
    quota_basis: str = _RUN.quota_basis
    quota_size_exponent: float | None = _RUN.quota_size_exponent
    quota_inertia: float = _RUN.quota_inertia
    min_share: float = _RUN.min_share
    bt_mutation_rate: float = _RUN.bt_mutation_rate
    bt_subtree_prob: float = 0.05
    bt_point_count: int = 1
    bt_point_on_nodes: bool = _RUN.bt_point_on_nodes
    point_opcode_weights: tuple[float, ...] = (1.0,) * 12 + (0.5, 0.5)
    subtree_leaf_prob: float = 0.5
    subtree_max_leaves: int = 3
    hw_sigma: float = _RUN.hw_sigma
    social_sigma: float = _RUN.social_sigma
    p_categorical: float = _RUN.p_categorical
    p_effector: float | None = _RUN.p_effector
    effector_flip: str = _RUN.effector_flip
    p_tag_flip: float | None = _RUN.p_tag_flip
    p_gene_mutation: float = _RUN.p_gene_mutation
