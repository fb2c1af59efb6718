"""Config migrations: a config table written by any version read as this version's (the one
place config migrations live)."""

from __future__ import annotations

from typing import Any

from ..coevo.config import SwarmCoDeConfig

#: Settings of configs saved before `quota_basis` and the mutation steps were config keys.
LEGACY_DEFAULTS = {"quota_basis": "mean", "hw_sigma": 0.1, "social_sigma": 0.1,
                   "p_categorical": 0.1}

#: Episode lengths of built-in scenarios whose default has changed since runs began pinning
#: theirs in config.toml; a saved config without `ticks` ran with these.
LEGACY_EPISODE_TICKS = {"one-niche": 250, "two-niche": 250, "four-niche": 250}


def migrate_config(d: Any) -> Any:
    """A config table written by any version -> this version's keys, with the values the run
    was made with for every setting added since (the one place config migrations live).
    Anything but a table is returned as it is (`SwarmCoDeConfig.from_dict` refuses it)."""
    if not isinstance(d, dict):
        return d
    d = {k: (None if v == "none" else v) for k, v in d.items()}
    if "quota_basis" not in d:
        # written before these settings existed: keep the run's original algorithm
        d = {**LEGACY_DEFAULTS, **d}
    if "p_tag_flip" not in d:
        # written before the tag flip rate was a setting: it was one bit in L per child
        tag_length = d.get("tag_length", SwarmCoDeConfig.tag_length)
        d["p_tag_flip"] = 1.0 / int(tag_length) if isinstance(tag_length, int) else None
    if "min_share" not in d:
        d["min_share"] = 0.0     # written before the quota threshold existed
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
    return d
