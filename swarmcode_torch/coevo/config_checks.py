"""Which values each run setting takes: the checks behind `SwarmCoDeConfig.validate`.

Each check reads a config by its field names and raises `SettingError` for the first setting it
refuses, in the order of the tables below (the message a bad config gets does not depend on how
the checks are grouped). The tables are re-exported by `coevo.config`, where the application
imports them.
"""

from __future__ import annotations

import math
from typing import Any


class SettingError(ValueError):
    """An invalid setting: `key` names it, `problem` says what is wrong ("must be >= 1, got 0");
    the message is the two together. The application respells the key as its options do."""

    def __init__(self, key: str, problem: str):
        super().__init__(f"{key} {problem}")
        self.key, self.problem = key, problem


#: The settings that name one of a few choices (validated in `SwarmCoDeConfig.validate`).
CHOICES = {
    "objective": ("fitness", "roi"),
    "partners_per_niche": ("all", "one"),
    "partner_admission": ("open", "substitute"),
    "admission_basis": ("elites", "members"),
    "refound_source": ("partners", "designs", "random"),
    "share_basis": ("fitness", "marginal", "fitness+marginal", "marginal/slot"),
}
#: Choices of settings that may also be unset.
OPTIONAL_CHOICES = {"preset": ("default", "paper")}

#: The largest seed a run's generator takes (torch.Generator.manual_seed accepts 64 bits; a seed
#: is kept non-negative and below 2**63 so that it reads back the same everywhere).
MAX_SEED = 2**63 - 1

#: Lower bounds of the integer settings; the sizes' upper bound is the memory their evaluation
#: needs.
LOWER_BOUNDS = {
    "generations": 1,
    "population": 2,
    "trials": 1,
    "tag_length": 1,
    "bt_length": 4,
    "max_elite": 1,
    "swarm_size": 1,
    "ticks": 1,
    "seed": 0,
    "essential_floor": 0,
    "refound_after": 0,
    "demote_far_after": 0,
    "demote_after": 1,
    "equal_quotas_until": 0,
    "best_team_floor": 0,
    "knockout_floor": 0,
    "reeval_trials": 0,
}

#: Settings that are finite numbers >= 0 (the weights of the speciation distance too: their keys
#: are given by the caller, from `DistanceWeights`).
NON_NEGATIVE = (
    "delta",
    "lam",
    "hw_sigma",
    "social_sigma",
    "min_share",
    "w_delivery",
    "w_collab_bonus",
    "w_pickup",
    "w_energy",
    "w_proximity",
    "w_closeness",
    "fitness_floor",
)

#: Settings that must be > 0 (besides being finite numbers >= 0).
POSITIVE = ("delta", "gamma")

#: Settings that are probabilities or factors in [0, 1]; an optional one may be unset.
UNIT_INTERVAL = (
    "p_marginal",
    "knockout_credit",
    "team_partners_margin",
    "best_team_tie",
    "knockout_pairs",
    "quota_size_exponent",
    "essential_below",
    "alpha",
    "p_categorical",
    "p_effector",
    "p_tag_flip",
    "bt_mutation_rate",
    "p_gene_mutation",
    "inactive_factor",
)

#: Upper bounds of settings that memory does not bound (the application checks memory first
#: (`app.runs.check_memory`), so that sizes far too large for memory are told what they would need).
UPPER_BOUNDS = {
    "generations": 10_000_000,
    "ticks": 1_000_000,
    "tag_length": 4096,
    "bt_length": 4096,
    "max_elite": 1_000_000,
    "population": 100_000_000,
    "trials": 1_000_000,
    "reeval_trials": 10_000,
    "swarm_size": 10_000_000,
    # numbers the float32 tensors must hold with room to spare (delta=1e300 is inf
    # there; social_sigma=1e300 makes NaN genes)
    "budget": 1e15,
    "delta": 1e6,
    "lam": 1e6,
    "hw_sigma": 1e6,
    "social_sigma": 1e6,
    "min_share": 1e9,
    "essential_floor": 1_000_000,
    "refound_after": 10_000_000,
    "demote_far_after": 10_000_000,
    "demote_after": 10_000_000,
    "equal_quotas_until": 10_000_000,
    "best_team_floor": 1_000_000,
    "knockout_floor": 1_000_000,
    "w_tag": 1e6,
    "w_hw": 1e6,
    "w_bt": 1e6,
    "w_tool": 1e6,
    "w_size": 1e6,
    "gamma": 1e3,
    # a team-episode's raw fitness is a float32 sum of these times counts
    "w_delivery": 1e12,
    "w_collab_bonus": 1e12,
    "w_pickup": 1e12,
    "w_energy": 1e12,
    "w_proximity": 1e12,
    "w_closeness": 1e12,
    "fitness_floor": 1e12,
}

_ACCEPTS = {bool: (bool,), int: (int,), float: (int, float), str: (str,)}
_KIND_TEXT = {bool: "true or false", int: "an integer", float: "a number", str: "a string"}


def check_types(cfg: Any, setting_types: dict[str, tuple[type, bool]]) -> None:
    """Each setting of `setting_types` (name -> (its type, whether None is allowed)) set, where it
    must be, and of its type (a bool is not an integer; an integer is a number)."""
    for name, (kind, optional) in setting_types.items():
        v = getattr(cfg, name)
        if v is None:
            if not optional:
                raise SettingError(name, "must be set")
            continue
        if not isinstance(v, _ACCEPTS[kind]) or (isinstance(v, bool) and kind is not bool):
            raise SettingError(name, f"must be {_KIND_TEXT[kind]}, got {v!r}")


def check_names(cfg: Any) -> None:
    """The settings that name something: budget, scenario, fitness function, the choices, the
    device."""
    if cfg.budget is not None:
        if not math.isfinite(cfg.budget):
            raise SettingError("budget", f"must be a finite number, got {cfg.budget}")
        if cfg.budget <= 0:
            raise SettingError("budget", f"must be > 0, got {cfg.budget:g}")
    if not cfg.scenario:
        raise SettingError("scenario", "must name a scenario")
    if cfg.fitness_function is not None and not cfg.fitness_function.strip():
        raise SettingError("fitness_function", "must name a function or be unset")
    for key, opts in CHOICES.items():
        v = getattr(cfg, key)
        if v not in opts:
            one_of = ", ".join(map(repr, opts[:-1])) + f" or {opts[-1]!r}"
            raise SettingError(key, f"must be {one_of}, got {v!r}")
    for key, opts in OPTIONAL_CHOICES.items():
        v = getattr(cfg, key)
        if v is not None and v not in opts:
            raise SettingError(key, f"must be {' or '.join(map(repr, opts))} or unset, got {v!r}")
    dev = cfg.device
    if dev not in ("auto", "cpu", "cuda") and not (
        dev.startswith("cuda:") and dev[5:].isdigit() and dev[5:].isascii()
    ):
        raise SettingError("device", f"must be auto, cpu, cuda or cuda:N, got {dev!r}")


def check_ranges(cfg: Any, distance_keys: tuple[str, ...]) -> None:
    """The numbers' lower bounds and intervals (`LOWER_BOUNDS`, the seed's `MAX_SEED`,
    `NON_NEGATIVE` and `distance_keys`, `POSITIVE`, `UNIT_INTERVAL`); NaN and infinities are
    refused where a finite number is meant."""
    for key, lo in LOWER_BOUNDS.items():
        v = getattr(cfg, key)
        if v is not None and v < lo:
            raise SettingError(key, f"must be >= {lo}, got {v}")
    if cfg.seed > MAX_SEED:
        raise SettingError("seed", f"must be in [0, {MAX_SEED}] (2**63 - 1), got {cfg.seed}")
    for key in (*NON_NEGATIVE, *distance_keys):
        v = getattr(cfg, key)
        if not (v >= 0 and math.isfinite(v)):  # also refuses nan
            raise SettingError(key, f"must be a finite number >= 0, got {v}")
    for key in POSITIVE:
        v = getattr(cfg, key)
        if not v > 0:
            raise SettingError(key, f"must be a finite number > 0, got {v}")
    for key in UNIT_INTERVAL:
        v = getattr(cfg, key)
        if v is None:  # an optional one left unset (`p_effector`)
            continue
        if not (v >= 0 and math.isfinite(v)):
            raise SettingError(key, f"must be a finite number in [0, 1], got {v}")
        if v > 1:
            raise SettingError(key, f"must be <= 1 (a number in [0, 1]), got {v}")


def check_upper_bounds(cfg: Any) -> None:
    """`SettingError` for a setting above its upper bound (`UPPER_BOUNDS`)."""
    for key, hi in UPPER_BOUNDS.items():
        v = getattr(cfg, key)
        if v is not None and v > hi:
            fmt = "g" if isinstance(hi, float) else "d"
            raise SettingError(key, f"must be <= {hi:{fmt}}, got {v:{fmt}}")
