"""The machinery of option declarations: an option of a command is one `Opt` (its name, type,
default, bounds, help and what it sets), and everything else is derived from a table of them
(`run_options.RUN_OPTIONS`): the Typer options (`options.command`), the keywords of
`swarmcode_torch.evolve` (`api_signature`), the config keys an option sets (`Values.config_keys`),
the intervals (`Intervals`) and the bound checks with their messages (`check_values`).

No Typer or Rich here: the Python API imports this module."""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any


class _Unset:
    """The default of an API keyword that leaves the config's value as it is."""

    _instance: _Unset | None = None

    def __new__(cls) -> _Unset:
        if cls._instance is None:
            cls._instance = super().__new__(cls)
        return cls._instance

    def __repr__(self) -> str:
        return "UNSET"

    def __reduce__(self) -> str:
        return "UNSET"


#: An API keyword not given: the config (or the preset) decides.
UNSET: Any = _Unset()
#: `Opt.api_default` not given: the API takes the command line's default.
SAME: Any = object()


@dataclass(frozen=True)
class Opt:
    """One option, declared once.

    name: the Python name (the API keyword, the key of `Values`); the command line spells it
        `--name-with-dashes` unless `flags` says otherwise (`--set`, `--compile/--no-compile`).
    type, default, help, metavar, complete: as Typer reads them (None: not given).
    low: the smallest value allowed (checked by `check_values`, named in the message); `zero`:
        what 0 means, where that is the bound ("never", "none").
    setting: the config key (`SwarmCoDeConfig`) the option sets when given (not None).
    interval: the `Intervals` field it fills.
    commands: the commands that take it; `variants`: per command, what differs there (help,
        default).
    api: whether `swarmcode_torch.evolve` takes it as a keyword, annotated `api_type` (default:
        `type`), with `api_default` (default: `default`; `UNSET` for a setting: the config's).
    to_value: the parsed value as the config or the run takes it (an enum's value).
    """

    name: str
    type: Any
    default: Any = None
    help: str = ""
    flags: tuple[str, ...] = ()
    metavar: str | None = None
    complete: Callable[[str], list[str]] | None = None
    low: float | None = None
    zero: str | None = None
    setting: str | None = None
    interval: str | None = None
    commands: tuple[str, ...] = ("evolve",)
    variants: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    api: bool = False
    api_type: str | None = None
    api_default: Any = SAME
    to_value: Callable[[Any], Any] | None = None

    @property
    def spelling(self) -> str:
        """How the command line names it: --population, --set, --from."""
        if self.flags:
            return self.flags[0].split("/")[0]
        return "--" + self.name.replace("_", "-")

    def value(self, v: Any) -> Any:
        """`v` as the config or the run takes it (None stays None)."""
        return v if v is None or self.to_value is None else self.to_value(v)

    def keyword(self) -> inspect.Parameter:
        """The option as a keyword-only parameter of the API."""
        default = self.api_default
        if default is SAME:
            default = UNSET if self.setting is not None else self.default
        annotation = self.api_type or _type_text(self.type)
        return inspect.Parameter(
            self.name, inspect.Parameter.KEYWORD_ONLY, default=default, annotation=annotation
        )


def _type_text(t: Any) -> str:
    return t.__name__ if isinstance(t, type) else str(t).replace("typing.", "")


def for_command(options: Iterable[Opt], command: str) -> tuple[Opt, ...]:
    """The options `command` takes, in declared order, each with its variant there."""
    return tuple(
        replace(o, **o.variants.get(command, {})) for o in options if command in o.commands
    )


@dataclass(frozen=True)
class Intervals:
    """The generations between a run's periodic outputs: checkpoints, log lines off a terminal,
    TensorBoard replay images (0: never), composition figures, snapshots (0: none). One value
    that the command line and the API pass on; the options that fill it (`Opt.interval`) hold
    the defaults and the bounds."""

    checkpoint: int
    log: int
    render: int
    figure: int
    snapshot: int


class Values(Mapping[str, Any]):
    """The values of a command's options, by name (`values.population`, `values["seed"]`),
    with what is derived from them: the config keys they set (`config_keys`), the `Intervals`.
    No option may be named as one of its methods or `options`."""

    def __init__(self, options: Iterable[Opt], given: Mapping[str, Any]):
        self.options = {o.name: o for o in options}
        clash = [n for n in self.options if hasattr(Values, n) or n == "options"]
        if clash:
            raise TypeError(f"option name(s) taken by Values: {', '.join(clash)}")
        unknown = set(given) - set(self.options)
        if unknown:
            raise TypeError(f"unknown option(s): {', '.join(sorted(unknown))}")
        self._values = {n: given.get(n, o.default) for n, o in self.options.items()}

    def __getitem__(self, name: str) -> Any:
        return self._values[name]

    def __getattr__(self, name: str) -> Any:
        try:
            return self.__dict__["_values"][name]
        except KeyError:
            raise AttributeError(name) from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __repr__(self) -> str:
        return f"Values({self._values!r})"

    def replace(self, **changes: Any) -> Values:
        """A copy with `changes` (option names) made."""
        return Values(self.options.values(), {**self._values, **changes})

    def converted(self) -> dict[str, Any]:
        """Every value as the config or the run takes it (`Opt.to_value`)."""
        return {n: o.value(self._values[n]) for n, o in self.options.items()}

    def config_keys(self, skip: Iterable[str] = ()) -> dict[str, Any]:
        """{config key: value} of the setting options that are given (not None), but `skip`."""
        skip = set(skip)
        return {
            o.setting: o.value(self._values[n])
            for n, o in self.options.items()
            if o.setting is not None and n not in skip and self._values[n] is not None
        }

    def intervals(self, defaults: Iterable[Opt] = ()) -> Intervals:
        """The `Intervals` of these values; a field no option here fills comes from `defaults`
        (an option table)."""
        by_field = {o.interval: o.default for o in defaults if o.interval is not None}
        by_field.update(
            {o.interval: self._values[n] for n, o in self.options.items() if o.interval}
        )
        return Intervals(**{f.name: by_field[f.name] for f in fields(Intervals)})


def check_values(
    options: Iterable[Opt], values: Mapping[str, Any], spell: Callable[[Opt], str] | None = None
) -> None:
    """Each value of an option with a lower bound (`Opt.low`) checked: TypeError for a value
    that is not a number of the option's kind (an integer for an int option; not a bool),
    ValueError below the bound; the message names the option as `spell` does (default: its
    Python name, as the API takes it)."""
    spell = spell or (lambda o: o.name)
    for o in options:
        v = values.get(o.name)
        if o.low is None or v is None:
            continue
        whole = o.type is int or o.type == (int | None)
        if isinstance(v, bool) or not isinstance(v, int if whole else (int, float)):
            kind = "an integer" if whole else "a number"
            raise TypeError(f"{spell(o)} must be {kind}, got {v!r:.40}")
        if v < o.low:
            raise ValueError(f"{spell(o)} must be >= {o.low:g}{_what(o)}, got {v}")


def _what(o: Opt) -> str:
    """What the bound's value means, where it is special: (0: never)."""
    return f" (0: {o.zero})" if o.low == 0 and o.zero else ""


def api_signature(
    func: Callable, options: Iterable[Opt], before: str = "reporters"
) -> inspect.Signature:
    """The signature of `func` as written (before `declare_keywords`) with the keywords of
    `options` (those with `api`) inserted before its parameter `before`."""
    sig = getattr(func, "__own_signature__", None) or inspect.signature(func)
    own = list(sig.parameters.values())
    at = next((i for i, p in enumerate(own) if p.name == before), len(own))
    added = [o.keyword() for o in options if o.api]
    names = {p.name for p in own}
    clash = [p.name for p in added if p.name in names]
    if clash:
        raise TypeError(f"{func.__name__} declares {', '.join(clash)} itself")
    return sig.replace(parameters=[*own[:at], *added, *own[at:]])


def declare_keywords(func: Callable, options: Iterable[Opt]) -> None:
    """Show the keywords of `options` in `func`'s signature (`api_signature`), as
    `inspect.signature`, `help()` and the documentation read it; `func` takes them in its
    `**kwargs` (`api_values`)."""
    sig = api_signature(func, options)
    func.__own_signature__ = getattr(func, "__own_signature__", None) or inspect.signature(func)  # type: ignore[attr-defined]
    func.__signature__ = sig  # type: ignore[attr-defined]


def api_values(options: Iterable[Opt], kwargs: dict[str, Any]) -> tuple[Values, dict[str, Any]]:
    """The API's keywords split: (the `Values` of the options it declares that set no config
    key, each given or its default; the config keys: those of the setting options given (not
    left at an UNSET or None default) and the other keywords, as given)."""
    opts = [o for o in options if o.api]
    own: dict[str, Any] = {}
    settings: dict[str, Any] = {}
    for o in opts:
        default = o.keyword().default
        v = kwargs.pop(o.name, default)
        if o.setting is None:
            own[o.name] = v
        elif not (v is default and default in (UNSET, None)):
            settings[o.setting] = v
    return Values([o for o in opts if o.setting is None], own), {**settings, **kwargs}
