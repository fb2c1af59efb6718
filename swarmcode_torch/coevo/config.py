"""The settings of a SwarmCoDe run, each with its one default and its range.

`SwarmCoDeConfig` is what a run is (config.toml holds its fields, flat). The algorithm reads it
through three parts built from it by field name, never by a hand-written copy:

    cfg.evaluation(num_robots, episode_ticks) -> EvalConfig   how teams are built and scored
    cfg.speciation                            -> SpeciationParams
    cfg.reproduction                          -> ReproductionParams

A part's setting that is also a run setting takes the run's default (`SwarmCoDeConfig.delta`
and so on), so `ReproductionParams()` in a notebook is the algorithm a default run uses.
Which values a setting takes is checked in `config_checks.py` (`SettingError`, the bounds),
the presets are in `presets.py`; their names are importable from here. Migrations of configs
written by older versions are the application's (`app.runs`).
"""

from __future__ import annotations

import typing
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

from .config_checks import (
    CHOICES,
    MAX_SEED,
    OPTIONAL_CHOICES,
    UPPER_BOUNDS,
    SettingError,
    check_names,
    check_ranges,
    check_types,
    check_upper_bounds,
)
from .presets import PRESETS

__all__ = [
    "CHOICES",
    "DISTANCE_KEYS",
    "FITNESS_KEYS",
    "MAX_SEED",
    "OPTIONAL_CHOICES",
    "PRESETS",
    "SETTING_TYPES",
    "UPPER_BOUNDS",
    "DistanceWeights",
    "EvalConfig",
    "FitnessWeights",
    "ReproductionParams",
    "SettingError",
    "SpeciationParams",
    "SwarmCoDeConfig",
    "preset_config",
    "with_overrides",
]


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
    reeval_trials: int = 10
    """Fresh environments each generation's best team is re-evaluated on before it may become
    the run's best team: the run records the team of the best re-evaluated mean (summary.json's
    `best_fitness`, with its 95 % interval), not the luckiest single evaluation. What is
    recorded only; evolution is the same for every value. 0: no re-evaluation, the best team is
    the highest single evaluation (as before 0.8, and for configs written before the key)."""
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
    """The cap of a species' elite count max(1, min(max_elite, floor(size / 5) + 1)) (the
    paper's E)."""
    dominance: bool = True
    """Sample team slots by the dominance genes; False: uniformly (an ablation)."""
    quota_size_exponent: float | None = 0.75
    """Each species' offspring quota is proportional to its mean fitness times its size to this
    power (1: its total fitness; 0: its mean fitness, NEAT's fitness sharing); for an exponent
    below 1 a species' size settles where it is proportional to its mean fitness to the power
    1 / (1 - exponent). Unset (none): proportional to its total fitness, the paper's quota
    (beyond the paper; docs/MODEL.md)."""
    min_share: float = 1.0
    """A species whose quota share is below this many individuals gets no slot (0: none)."""
    admission_basis: str = "members"
    """Whose gate results make a species' gated share in partner admission (probation,
    demotion, the essential floor): "elites", its members carried over unchanged where it has
    any (fresh offspring, some broken by mutation, are gated whatever the species does), or
    "members", all of them (the default; "elites" was not adopted: docs/MODEL.md)."""
    essential_floor: int = 0
    """Offspring quota floor of an essential species: a partner whose members beat their
    baselines (the moving average of its gated share below the admission threshold, 0.3), i.e.
    whose robots do a job no partner's robots can do. It keeps at least this many slots and is
    exempt from `min_share`, so that the holder of a hard niche, whose mean fitness may be lower
    than the others', is not starved out. Needs `partner_admission = "substitute"` (it reads the
    admission's gate statistics); 0: no floor (the default; not adopted: docs/MODEL.md)."""
    essential_below: float = 0.3
    """With `essential_floor`: a partner is essential while its gated share's moving average is
    below this (0.3, the admission threshold; 0.5, the clash threshold of two substitutes)."""
    refound_after: int = 0
    """Re-founding (`coevo.refound`): the champion of a species that dies while a partner (its
    members beat their baselines) is archived, and this many generations after its death a
    few offspring become copies of it, founding a species with a trial quota floor; 0: never
    (the default). Needs `partner_admission = "substitute"`."""
    refound_source: str = "partners"
    """What re-founding (`refound_after`) archives: "partners", the champions of species dying
    as partners beating their baselines, at least 5 generations old (the default); "designs",
    the champion of any species dying as the only champion of its design cell (effector, one of
    three radius bands), re-founded while the cell is empty, against early lock-in; "random",
    an explorer: copies of the generation's best with hardware genes drawn as generation 0's."""
    team_partners: bool = False
    """The species of the previous generation's best team are partners of every focal, besides
    those its tag and selectivity choose; False: partners by tag alone (the paper, the default)."""
    team_partners_margin: float = 0.0
    """With `team_partners`: only those of the best team's species whose knock-out costs it
    more than this fraction of its score (`coevo.knockout`); 0: all of them."""
    best_team_tie: float = 0.0
    """The generation's best team (reported, and read by `team_partners` and the knock-outs): of
    the focal teams within this fraction of the highest gated fitness, one of the fewest species,
    the highest of those; 0: the highest (the default)."""
    best_team_floor: int = 0
    """Offspring quota floor of every species with a robot in the generation's best team (the
    focal team of the individual of the highest gated fitness): it keeps at least this many
    slots, exempt from `min_share`, not starved out while the best team uses it; 0: none."""
    knockout_credit: float = 0.0
    """Knock-out credit (`coevo.knockout`): each generation the best team is evaluated again
    beside one team per species with that species' slots re-filled from the team's other
    slots; a species whose knock-out costs the team more than this fraction of its score gets
    the share of the next generation that the species of the highest mean fitness would get at
    its size (selection within species unchanged); 0: off (the default). A holder the best team
    needs is paid as the best species is; a substitute (its slots go to one doing its job) not."""
    knockout_floor: int = 0
    """With `knockout_credit`: the species credited by their knock-out keep a quota floor of
    this many slots (exempt from `min_share`) instead of the lift of their share; 0: the lift."""
    knockout_pairs: float = 0.0
    """Demotion of substitute pairs by knock-out (`coevo.knockout.demote_substitutes`): each
    generation the best team is evaluated again with each of its species knocked out and with
    each pair of them knocked out together (slots re-filled from the team's other slots); two
    partners whose knock-outs each cost the team at most this fraction of its score, but whose
    joint knock-out costs more, stand in for each other, and the lower-ranked (the smaller, then
    the younger) stops being a partner and is on probation again, at most one a generation; 0:
    off (the default). The admission's substitution test without design distance, for
    duplicates whose designs differ by more than δ. Needs `partner_admission = "substitute"`."""
    share_basis: str = "fitness"
    """What a species' offspring share follows: "fitness", its members' mean smoothed fitness
    (the default), or "marginal", their mean marginal contribution this generation, the focal
    team's score less the baseline's (where the nearest partner refills their slots), at least
    0 (selection within species still reads fitness). A holder whose own teams score low but
    that does a job no partner does is paid for that job; a substitute, whose slots its partner
    fills as well, is not. "fitness+marginal": the sum of the two, a member's fitness plus its
    marginal contribution. "marginal/slot": the marginal contribution divided by the slots the
    member's design fills in its focal team, the job done per robot. (Not 0.6's retired
    `quota_basis`, whose values were "sum" and "mean".)"""
    equal_quotas_until: int = 0
    """Before this generation every species gets the same share of the next generation
    (offspring quotas equal, not by fitness; selection within a species is unchanged); 0: never
    (the default). NEAT's protection of young species: a design that can do a hard job but does
    it badly at first (a hard niche's holder in random teams) is not starved before it improves."""
    demote_far_after: int = 0
    """From this generation on, the admission's demotion of substitutes (`coevo.admission`)
    also pairs a partner with its nearest partner design of the same effector when that design
    is farther than δ (before it, and with 0, the default: only within δ, 0.7's rule): two
    partners of one effector that stand in for each other are told apart however they differ;
    the delay spares the first generations, when most species are gated half the time. Needs
    `partner_admission = "substitute"`."""
    substitute_effector: bool = False
    """Partner admission: a species' nearest partner design (its baseline's refill, and the one
    it may be a substitute of) is of its own effector where it has one; False: of any (0.7)."""
    demote_after: int = 2
    """Partner admission: the generations in a row a partner's gated-share average must stay
    above one half before it is a substitute of its nearest partner (2: 0.7's rule, the default)."""
    hw_sigma: float = 0.05
    """Mutation: Gaussian step of radius and operating points, as a fraction of their range."""
    social_sigma: float = 0.05
    """Mutation: Gaussian step of selectivity and dominance."""
    p_categorical: float = 0.02
    """Mutation: probability of resampling each tier and the effector."""
    p_effector: float | None = 0.005
    """Mutation: probability of resampling the effector (None: p_categorical, as the tiers); below
    the tiers' it makes effector flips, which found most late species, rarer (docs/MODEL.md)."""
    p_tag_flip: float = 0.01
    """Mutation: probability of flipping each tag bit."""
    bt_mutation_rate: float = 0.5
    """Mutation: probability that an offspring gets its behavior-tree mutation event."""
    p_gene_mutation: float = 0.2
    """Mutation: probability that each continuous gene of an offspring gets its Gaussian step."""
    partners_per_niche: str = "all"
    """Which species may be partners: "all" (the paper: any species whose tag the focal's
    selectivity accepts) or "one", a diagnostic reference, no part of SwarmCoDe, that tells the
    algorithm the task's niches: of the species whose elites lift the same package classes,
    only the largest."""
    partner_admission: str = "substitute"
    """When a species becomes and stays a partner (`coevo.admission`): "open", from its founding
    (the paper); "substitute", every focal's baseline re-fills its slots from its nearest
    partner design, a species founded after generation 0 is no one's partner until its members
    are seldom gated (its robots do what that partner's cannot), and a partner gated half the
    time or more is a substitute of its nearest partner, the lower-ranked of the two (smaller,
    then younger) stopping being a partner. Beyond the paper and scenario-agnostic: it reads
    genomes, species sizes and ages, and the gate's results (docs/MODEL.md)."""
    # the weights of the speciation distance D (paper Sec. III-A, `speciation.distance`)
    w_tag: float = 1.0
    """Speciation distance: weight of the tag term (H / L) ** gamma."""
    w_hw: float = 0.5
    """Speciation distance: weight of d_hw, the normalised distance of the operating points."""
    w_bt: float = 0.3
    """Speciation distance: weight of d_bt, the share of behavior-tree slots that differ."""
    w_tool: float = 0.35
    """Speciation distance: weight of d_tool (1 where the effectors differ)."""
    w_size: float = 0.7
    """Speciation distance: weight of d_size, the normalised difference of the radii."""
    gamma: float = 2.0
    """Speciation distance: exponent of the tag term (H / L) ** gamma (> 0)."""
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

    def validate(self, bounds: bool = True) -> None:
        """Raise `SettingError` (a ValueError) with a one-line message for an invalid setting: a
        value of the wrong type, out of its range, NaN or infinite where a finite number is
        meant. The message names the setting by its key (`SettingError.key`; the application
        respells it as its options do). `bounds=False` leaves out the upper bounds
        (`check_bounds`), so that the application can first tell a run far too large for memory
        what it would need."""
        check_types(self, SETTING_TYPES)
        check_names(self)
        check_ranges(self, DISTANCE_KEYS)
        if bounds:
            self.check_bounds()

    def check_bounds(self) -> None:
        """`SettingError` for a setting above its upper bound (`UPPER_BOUNDS`)."""
        check_upper_bounds(self)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SwarmCoDeConfig:
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
        values: dict[str, Any] = {k: (None if v == "none" else v) for k, v in d.items()}
        return cls(**values)

    def evaluation(self, num_robots: int, episode_ticks: int) -> EvalConfig:
        """How teams are scored, with the scenario's team size and episode length where the
        run leaves them unset."""
        return _part(
            EvalConfig,
            self,
            swarm_size=self.swarm_size or num_robots,
            ticks=self.ticks or episode_ticks,
            weights=self.fitness_weights,
        )

    @property
    def fitness_weights(self) -> FitnessWeights:
        """The raw-fitness weights of the run (`w_delivery`, ..., `fitness_floor`)."""
        return FitnessWeights(**{f: float(getattr(self, key)) for f, key in FITNESS_KEYS.items()})

    @property
    def distance_weights(self) -> DistanceWeights:
        """The weights of the speciation distance D (`w_tag`, ..., `gamma`)."""
        return DistanceWeights(**{k: float(getattr(self, k)) for k in DISTANCE_KEYS})

    @property
    def speciation(self) -> SpeciationParams:
        return _part(SpeciationParams, self, weights=self.distance_weights)

    @property
    def reproduction(self) -> ReproductionParams:
        return _part(ReproductionParams, self)


def preset_config(name: str = "default", **settings: Any) -> SwarmCoDeConfig:
    """The config of preset `name` (`PRESETS`) with `settings` (config keys) on top; ValueError
    naming the presets for an unknown name."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r} (presets: {', '.join(PRESETS)})")
    return replace(SwarmCoDeConfig(), **{**PRESETS[name], **settings, "preset": name})


#: SwarmCoDeConfig field -> (its type without None, whether None is allowed); from the resolved
#: annotations, not their text.
SETTING_TYPES: dict[str, tuple[type, bool]] = {}
for _name, _hint in typing.get_type_hints(SwarmCoDeConfig).items():
    _args = [a for a in typing.get_args(_hint) if a is not type(None)] or [_hint]
    SETTING_TYPES[_name] = (_args[0], type(None) in typing.get_args(_hint))

_RUN = SwarmCoDeConfig  # the run defaults, as class attributes


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
FITNESS_KEYS = {
    "W_delivery": "w_delivery",
    "W_collab_bonus": "w_collab_bonus",
    "W_pickup": "w_pickup",
    "W_energy": "w_energy",
    "W_proximity": "w_proximity",
    "W_closeness": "w_closeness",
    "inactive_factor": "inactive_factor",
    "floor": "fitness_floor",
}


@dataclass(frozen=True)
class EvalConfig:
    """How teams are built and scored (`evaluation.evaluate`)."""

    swarm_size: int  # robots per team
    ticks: int  # episode length
    trials: int = _RUN.trials  # random environments per team (focal and baseline share them)
    budget: float | None = _RUN.budget  # $; None: no budget penalty
    objective: str = _RUN.objective  # "fitness" or "roi" (fitness divided by team cost)
    lam: float = _RUN.lam  # budget penalty decay
    p_marginal: float = _RUN.p_marginal  # factor on fitness when the marginal contribution is <= 0
    max_elite: int = _RUN.max_elite  # the elite cap (partner elites are drawn from the elites)
    dominance: bool = _RUN.dominance  # False: uniform team composition (an ablation)
    partners_per_niche: str = _RUN.partners_per_niche  # "one": one partner species per capability
    weights: FitnessWeights = FitnessWeights()


@dataclass(frozen=True)
class DistanceWeights:
    """Weights of the genome distance D (paper Table "distance weights"); gamma is the tag-term
    exponent. Each is the run setting of the same name (`DISTANCE_KEYS`)."""

    w_tag: float = _RUN.w_tag
    w_hw: float = _RUN.w_hw
    w_bt: float = _RUN.w_bt
    w_tool: float = _RUN.w_tool
    w_size: float = _RUN.w_size
    gamma: float = _RUN.gamma


#: The run settings that give the distance weights (`DistanceWeights`' fields).
DISTANCE_KEYS = tuple(f.name for f in fields(DistanceWeights))


@dataclass(frozen=True)
class SpeciationParams:
    """Dynamic speciation (`speciation.speciate`): the threshold and the distance."""

    delta: float = _RUN.delta
    weights: DistanceWeights = DistanceWeights()


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
    quota_size_exponent: quotas proportional to mean fitness x size ** exponent (1: the total,
        0: the mean, NEAT's explicit fitness sharing); None: to the total of the members'
        (gated, penalised, smoothed) fitness, the paper's "total adjusted fitness".
    min_share: a species whose quota share is below this many individuals gets no slot.
    essential_floor: the quota floor of the species `reproduce` is told are essential (exempt
        from min_share); at most population // (2 * floor) of them, the least gated first.
    bt_mutation_rate: per-offspring probability of one BT mutation event (1.0: every offspring).
    bt_subtree_prob: fraction of BT mutation events that are subtree replacements (the rest point).
    bt_point_count: point re-draws of one point mutation, each of a uniform slot among the
        tree's nodes (its non-NOP slots; slot 0 of an all-NOP program; may repeat): the NOP
        padding is not a node, so it stays padding (the paper mutates tree nodes).
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
    quota_size_exponent: float | None = _RUN.quota_size_exponent
    min_share: float = _RUN.min_share
    essential_floor: int = _RUN.essential_floor
    bt_mutation_rate: float = _RUN.bt_mutation_rate
    bt_subtree_prob: float = 0.05
    bt_point_count: int = 1
    point_opcode_weights: tuple[float, ...] = (1.0,) * 12 + (0.5, 0.5)
    subtree_leaf_prob: float = 0.5
    subtree_max_leaves: int = 3
    hw_sigma: float = _RUN.hw_sigma
    social_sigma: float = _RUN.social_sigma
    p_categorical: float = _RUN.p_categorical
    p_effector: float | None = _RUN.p_effector
    p_tag_flip: float | None = _RUN.p_tag_flip
    p_gene_mutation: float = _RUN.p_gene_mutation
