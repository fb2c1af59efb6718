"""How the command line spells the run settings: the options that set a config key, `--set
KEY=VALUE` for the rest, and the names its error messages use."""

from __future__ import annotations

from typing import Any

from ..coevo.config import SETTING_TYPES, SettingError
from . import run_options


def option_keys() -> frozenset[str]:
    """Config keys that `parse_settings` refuses because the command line has an option for them
    (`run_options.RUN_OPTIONS`: the options with a `setting`)."""
    return frozenset(run_options.option_keys())


#: Config keys that only the Python API sets (`parse_settings` refuses them), and how.
API_KEYS = {
    "fitness_function": "a fitness function is given from Python: "
    "swarmcode_torch.evolve(fitness=fn) (examples/custom_fitness.py)"
}


def option_names(overrides: dict[str, str] | None = None) -> dict[str, str]:
    """Config key -> how the command line sets it (--population, --set delta), for
    `setting_message` and `runs.check_memory`; `overrides` respells some (a sweep's
    --seeds)."""
    options = run_options.option_keys()
    names = {k: (options[k] if k in options else f"--set {k}") for k in SETTING_TYPES}
    names.update(overrides or {})
    return names


def setting_message(e: SettingError, names: dict[str, str] | None = None) -> str:
    """The one-line message of an invalid setting, the key spelled as `names` spells it
    (`option_names`: --population, --set delta), else as the key itself."""
    return f"{(names or {}).get(e.key, e.key)} {e.problem}"


def parse_settings(pairs: list[str], option_names: dict[str, str] | None = None) -> dict[str, Any]:
    """["key=value", ...] -> {key: typed value} for the algorithm's config keys (e.g. delta=0.5,
    p_tag_flip=0.0625, w_tool=0.5; `none` unsets a key that may be unset, such as
    quota_size_exponent=none); ValueError with a one-line message for a malformed
    pair, an unknown key, a key that has its own option (named `option_names[key]`, default
    --key), or a value of the wrong type."""
    out: dict[str, Any] = {}
    taken = option_keys()
    for pair in pairs:
        key, sep, text = pair.partition("=")
        key, text = key.strip().replace("-", "_"), text.strip()
        if not sep or not key or not text:
            raise ValueError(f"--set expects KEY=VALUE, got {pair!r}")
        if key in out:
            raise ValueError(f"--set {key} is given twice")
        if key in taken:
            option = (option_names or {}).get(key, "--" + key.replace("_", "-"))
            raise ValueError(f"--set {key}: use the {option} option")
        if key in API_KEYS:
            raise ValueError(f"--set {key}: {API_KEYS[key]}")
        if key not in SETTING_TYPES:
            settable = ", ".join(sorted(set(SETTING_TYPES) - taken - set(API_KEYS)))
            raise ValueError(f"--set: unknown key {key!r} (settable: {settable})")
        kind, nullable = SETTING_TYPES[key]
        try:
            if nullable and text.lower() == "none":
                out[key] = None  # unset (e.g. quota_size_exponent=none)
            elif kind is bool:
                if text.lower() not in ("true", "false"):
                    raise ValueError
                out[key] = text.lower() == "true"
            else:
                out[key] = kind(text)
        except ValueError:
            raise ValueError(
                f"--set {key}: expected a value of type {kind.__name__}, got {text!r}"
            ) from None
    return out
