"""Config migrations: a config table written by any version read as this version's (the one
place config migrations live)."""

from __future__ import annotations

from typing import Any

from ..coevo.config import SwarmCoDeConfig
from .files import RunError

#: Settings of configs saved before `quota_basis` and the mutation steps were config keys.
LEGACY_DEFAULTS = {
    "quota_basis": "mean",
    "hw_sigma": 0.1,
    "social_sigma": 0.1,
    "p_categorical": 0.1,
}

#: Episode lengths of built-in scenarios whose default has changed since runs began pinning
#: theirs in config.toml; a saved config without `ticks` ran with these.
LEGACY_EPISODE_TICKS = {"one-niche": 250, "two-niche": 250, "four-niche": 250}


def migrate_config(d: Any, keep_retired: bool = False) -> Any:
    """A config table written by any version -> this version's keys, with the values the run
    was made with for every setting added since (the one place config migrations live), less
    the retired settings (`drop_retired_settings`; kept with `keep_retired`). Anything but a
    table is returned as it is (`SwarmCoDeConfig.from_dict` refuses it)."""
    if not isinstance(d, dict):
        return d
    d = {k: (None if v == "none" else v) for k, v in d.items()}
    # written before 0.8: no quota floor for essential species
    d.setdefault("essential_floor", 0)
    d.setdefault("admission_basis", "members")
    d.setdefault("essential_below", 0.3)
    d.setdefault("refound_after", 0)
    d.setdefault("refound_source", "partners")
    d.setdefault("demote_far_after", 0)
    d.setdefault("demote_after", 2)
    d.setdefault("substitute_effector", False)
    d.setdefault("equal_quotas_until", 0)
    d.setdefault("best_team_floor", 0)
    d.setdefault("best_team_tie", 0.0)
    d.setdefault("team_partners", False)
    d.setdefault("team_partners_margin", 0.0)
    d.setdefault("knockout_credit", 0.0)
    d.setdefault("knockout_floor", 0)
    d.setdefault("knockout_pairs", 0.0)
    d.setdefault("share_basis", "fitness")
    # written before 0.8: the best team was the highest single evaluation, never re-evaluated
    d.setdefault("reeval_trials", 0)
    if "w_tag" in d:
        # written since 0.7, which writes every key and none of the retired ones
        return d if keep_retired else drop_retired_settings(d)
    if "quota_basis" not in d:
        # written before these settings existed: keep the run's original algorithm
        d = {**LEGACY_DEFAULTS, **d}
    if "p_tag_flip" not in d:
        # written before the tag flip rate was a setting: it was one bit in L per child
        tag_length = d.get("tag_length", SwarmCoDeConfig.tag_length)
        d["p_tag_flip"] = 1.0 / int(tag_length) if isinstance(tag_length, int) else None
    if "min_share" not in d:
        d["min_share"] = 0.0  # written before the quota threshold existed
    # written before the paper-text fixes of d_hw and the tree mutation: the old behaviour
    d.setdefault("d_hw_tiers", True)
    d.setdefault("bt_point_on_nodes", False)
    d.setdefault("bt_mutation_rate", 1.0)
    d.setdefault("p_gene_mutation", 1.0)
    if "partners_per_niche" not in d:
        # written before 0.4: every species was a partner, and quotas were as quota_basis says
        # unless a quota_size_exponent was set (0.3.3)
        d["partners_per_niche"] = "all"
        d.setdefault("quota_size_exponent", None)
    # written before 0.5, which writes p_effector always ("none" unset): it was unset unless
    # the config names it
    d.setdefault("p_effector", None)
    # written before 0.6: every partner re-filled a focal's slots, and there were no presets
    d.setdefault("baseline_refill", "any")
    d.setdefault("partner_admission", "open")
    d.setdefault("preset", None)
    if d.get("ticks") is None and d.get("scenario") in LEGACY_EPISODE_TICKS:
        # written before runs pinned their episode length: the scenario's length of that time
        d["ticks"] = LEGACY_EPISODE_TICKS[d["scenario"]]
    return d if keep_retired else drop_retired_settings(d)


# ------------------------------------------------------------------ retired settings
#: Settings this version no longer has: key -> (the values that run as this version does, the
#: last version that ran the setting). Rejected experiments, and settings that kept behaviour
#: from before 0.2 for old runs; their results are in the research notes.
RETIRED_SETTINGS: dict[str, tuple[tuple[Any, ...], str]] = {
    "gate_margin": ((0, 0.0), "0.6.0"),
    "quota_inertia": ((0, 0.0), "0.6.0"),
    "effector_flip": (("gene",), "0.6.0"),
    "merge_species": ((False,), "0.6.0"),
    "evaluated_partners": ((False,), "0.6.0"),
    "baseline_refill": (("any",), "0.6.0"),
    "d_hw_tiers": ((False,), "0.6.0"),
    "bt_point_on_nodes": ((True,), "0.6.0"),
    # with quota_size_exponent set, quota_basis changed nothing (`retired_setting`)
    "quota_basis": (("sum",), "0.6.0"),
}
#: Retired values of settings this version keeps: (key, value) -> the last version that ran it.
RETIRED_VALUES = {("partner_admission", "gate"): "0.6.0"}


def retired_setting(d: dict) -> str | None:
    """For a migrated config table (`migrate_config` before it drops the retired keys): a
    one-line message naming the first setting whose value this version cannot run (a retired
    key at a value other than one that runs as this version does, or a retired value), with
    the last version that ran it; None if this version runs the config as it was run."""
    for key, (same, last) in RETIRED_SETTINGS.items():
        if key not in d:
            continue
        v = d[key]
        if key == "quota_basis" and d.get("quota_size_exponent") is not None:
            continue  # the exponent set the quotas
        if not any(v == ok and type(v) is type(ok) for ok in same):
            return (
                f"{key} = {v!r} is a retired setting that this version cannot run (last "
                f"run by swarmcode-torch {last})"
            )
    return retired_value(d)


def retired_value(d: dict) -> str | None:
    """A one-line message naming the first setting of a config table at a retired value
    (`RETIRED_VALUES`), which this version can neither run nor read; None if there is none."""
    for (key, value), last in RETIRED_VALUES.items():
        if d.get(key) == value:
            return (
                f"{key} = {value!r} is retired; this version cannot run it (last run by "
                f"swarmcode-torch {last})"
            )
    return None


def drop_retired_settings(d: dict) -> dict:
    """A migrated config table without the retired settings (`RETIRED_SETTINGS`): what a run
    directory records of them is read, not run (`retired_setting` tells a resume)."""
    return {k: v for k, v in d.items() if k not in RETIRED_SETTINGS}


def check_runnable(d: Any, source: str) -> None:
    """RunError naming the setting, for a config table (of any version) that holds a retired
    setting at a value this version cannot run (`retired_setting`)."""
    if not isinstance(d, dict):
        return
    problem = retired_setting(migrate_config(d, keep_retired=True))
    if problem:
        raise RunError(f"{source}: {problem}")
