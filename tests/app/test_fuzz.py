"""Fuzzing the command line: option values, --set values, scenario TOML fields and summary.json
fields, run in-process. Every case ends with exit 0 or with a one-line error and exit 2, never a
traceback.

The default run is small and deterministic (derandomize=True, ~20 examples a test, tiny runs when
a case is valid); `pytest -m fuzz` runs the same properties with many more random examples.
"""

from __future__ import annotations

import json
import math
import shutil
import sys
import tempfile
from importlib import resources
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from swarmcode_torch.app.cli import app

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

runner = CliRunner()
QUICK = settings(
    max_examples=20,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=list(HealthCheck),
)
LONG = settings(
    max_examples=300, deadline=None, database=None, suppress_health_check=list(HealthCheck)
)
#: A valid run as small as it gets; fuzzed options come after these and replace them.
TINY = [
    "--scenario",
    "one-niche",
    "--population",
    "4",
    "--swarm-size",
    "3",
    "--trials",
    "1",
    "--ticks",
    "5",
    "--generations",
    "1",
    "--render-every",
    "0",
    "--no-compile",
    "--device",
    "cpu",
]


def check(result) -> None:
    """exit 0, or exit 2 with a one-line 'Error: ...' on stderr; never a traceback."""
    assert "Traceback" not in result.output, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(
        result.exception
    )
    assert result.exit_code in (0, 2), (result.exit_code, result.output)
    if result.exit_code == 2:
        lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("Error: "), result.output


def invoke(args, logdir: Path):
    return runner.invoke(app, [str(a) for a in args] + ["--logdir", str(logdir)])


# ------------------------------------------------------------------ options
HOSTILE_NUMBERS = [
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "1e309",
    "1000000000000",
    str(2**64),
    "abc",
    "",
    "1.5",
]
OPTIONS = {
    "--budget": ["900", "3000", "1e15"] + HOSTILE_NUMBERS,
    "--population": ["4", "5"] + HOSTILE_NUMBERS,
    "--swarm-size": ["3", "4"] + HOSTILE_NUMBERS,
    "--trials": ["1"] + HOSTILE_NUMBERS,
    "--ticks": ["5", "8"] + HOSTILE_NUMBERS,
    "--generations": ["1"] + HOSTILE_NUMBERS,
    "--seed": ["0", "7", str(2**63 - 1), str(2**63)] + HOSTILE_NUMBERS,
    "--objective": ["fitness", "roi", "", "profit"],
    "--device": ["cpu", "tpu", "cuda:x", "cuda:99"],
    "--scenario": ["one-niche", "two-niche", "budget", "nowhere", "missing.toml", ""],
    "--checkpoint-every": ["1", "0", "-3", "x"],
    "--log-every": ["1", "0", "-1"],
    "--render-every": ["0", "-1"],
}
option_cases = st.dictionaries(
    st.sampled_from(sorted(OPTIONS)), st.none(), min_size=1, max_size=4
).flatmap(lambda d: st.fixed_dictionaries({k: st.sampled_from(OPTIONS[k]) for k in d}))


def _options(case: dict) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        args = ["evolve", *TINY]
        for k, v in case.items():
            args += [k, v]
        check(invoke(args, Path(tmp) / "runs"))


@settings(QUICK, max_examples=15)  # a valid case runs a generation: the dearest examples
@given(option_cases)
def test_fuzz_options(case):
    _options(case)


@pytest.mark.fuzz
@LONG
@given(option_cases)
def test_fuzz_options_long(case):
    _options(case)


# ------------------------------------------------------------------ --set values
SET_KEYS = [
    "delta",
    "p_marginal",
    "alpha",
    "lam",
    "max_elite",
    "tag_length",
    "bt_length",
    "min_share",
    "hw_sigma",
    "social_sigma",
    "p_categorical",
    "p_tag_flip",
    "bt_mutation_rate",
    "p_gene_mutation",
    "dominance",
    "cuda_graphs",
    "seed",
    "w_tag",
    "w_tool",
    "gamma",
    "w_delivery",
    "inactive_factor",
    "fitness_floor",
    "p_effector",
    "quota_size_exponent",
    "partners_per_niche",
    "partner_admission",
    "quota_basis",
    "unknown_key",
]
SET_VALUES = [
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "0.5",
    "1",
    "1.5",
    "4",
    "1e300",
    "1e400",
    "100000000000",
    "true",
    "false",
    "none",
    "x",
    "mean",
    "open",
    "substitute",
    "gate",
    "all",
    "one",
    "",
]
set_cases = st.lists(
    st.tuples(st.sampled_from(SET_KEYS), st.sampled_from(SET_VALUES)), min_size=1, max_size=3
)


def _settings(pairs) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        args = ["evolve", *TINY]
        for k, v in pairs:
            args += ["--set", f"{k}={v}"]
        check(invoke(args, Path(tmp) / "runs"))


@QUICK
@given(set_cases)
def test_fuzz_set_values(pairs):
    _settings(pairs)


@pytest.mark.fuzz
@LONG
@given(set_cases)
def test_fuzz_set_values_long(pairs):
    _settings(pairs)


# ------------------------------------------------------------------ scenario files
BUILTINS = {
    f.name[:-5]: tomllib.loads(f.read_text(encoding="utf-8"))
    for f in resources.files("swarmcode_torch").joinpath("scenarios").iterdir()
    if f.name.endswith(".toml")
}
MISSING = object()
HOSTILE_VALUES = [
    math.nan,
    math.inf,
    -math.inf,
    -1,
    0,
    -0.5,
    10**12,
    1e300,
    10**30,
    "x",
    True,
    [1.0],
    [1.0, math.nan],
    [5.0, 1.0],
    [-1.0, 2.0],
    [0.0, 1e9],
    {},
    MISSING,
]
TOP_KEYS = [
    "name",
    "description",
    "arena",
    "base_radius",
    "num_robots",
    "episode_ticks",
    "species_overhead",
    "obstacles",
    "packages",
    "colour",
]
PACKAGE_KEYS = [
    "kind",
    "count",
    "distance",
    "mass",
    "effector",
    "grips",
    "radius_band",
    "size",
    "distance_weighting",
    "extra",
]
OBSTACLE_KEYS = ["count", "radius", "extra"]


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return (
            "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
        )
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(v)


def to_toml(d: dict) -> str:
    """A scenario table as TOML (scalars and lists inline, tables and arrays of tables after)."""
    lines, tables = [], []
    for k, v in d.items():
        if isinstance(v, dict) and v and all(not isinstance(x, dict) for x in v.values()):
            tables.append(f"\n[{k}]\n" + "".join(f"{a} = {_toml_value(b)}\n" for a, b in v.items()))
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            for x in v:
                tables.append(
                    f"\n[[{k}]]\n" + "".join(f"{a} = {_toml_value(b)}\n" for a, b in x.items())
                )
        else:
            lines.append(f"{k} = {_toml_value(v)}")
    return "\n".join(lines) + "\n" + "".join(tables)


@st.composite
def scenario_cases(draw):
    name = draw(st.sampled_from(sorted(BUILTINS)))
    d = json.loads(json.dumps(BUILTINS[name]))  # a deep copy
    for _ in range(draw(st.integers(1, 2))):
        where = draw(st.sampled_from(["top", "package", "obstacles"]))
        value = draw(st.sampled_from(HOSTILE_VALUES))
        if where == "top":
            table, key = d, draw(st.sampled_from(TOP_KEYS))
        elif (
            where == "package"
            and isinstance(d.get("packages"), list)
            and d["packages"]
            and isinstance(d["packages"][0], dict)
        ):
            i = draw(st.integers(0, len(d["packages"]) - 1))
            table, key = d["packages"][i], draw(st.sampled_from(PACKAGE_KEYS))
        else:
            if not isinstance(d.get("obstacles"), dict):
                d["obstacles"] = {}
            table, key = d["obstacles"], draw(st.sampled_from(OBSTACLE_KEYS))
        if value is MISSING:
            table.pop(key, None)
        else:
            table[key] = value
    return name, d


def _scenario(case) -> None:
    name, d = case
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{name}-fuzzed.toml"
        path.write_text(to_toml(d))
        args = ["evolve", *TINY, "--scenario", path]
        check(invoke(args, Path(tmp) / "runs"))


def test_to_toml_round_trips_every_builtin():
    for d in BUILTINS.values():
        assert tomllib.loads(to_toml(d)) == d


@QUICK
@given(scenario_cases())
def test_fuzz_scenario_fields(case):
    _scenario(case)


@pytest.mark.fuzz
@LONG
@given(scenario_cases())
def test_fuzz_scenario_fields_long(case):
    _scenario(case)


# ------------------------------------------------------------------ summary.json read back
@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    logdir = tmp_path_factory.mktemp("fuzzruns")
    r = invoke(["evolve", *TINY], logdir)
    assert r.exit_code == 0, r.output
    (run,) = list(logdir.iterdir())
    return run


SUMMARY_VALUES = [
    None,
    "x",
    math.nan,
    -1,
    0,
    10**30,
    1e300,
    True,
    [],
    {},
    [{}],
    [7],
    [{"count": 1}],
]


@st.composite
def summary_cases(draw):
    top = draw(st.booleans())
    key = draw(
        st.sampled_from(
            [
                "best_fitness",
                "team_cost",
                "budget",
                "designs",
                "deliveries",
                "num_species",
                "best_generation",
            ]
            if top
            else [
                "count",
                "species",
                "effector",
                "radius",
                "chassis_tier",
                "torque_point",
                "dominance",
                "cost",
                "bt",
            ]
        )
    )
    return top, key, draw(st.sampled_from(SUMMARY_VALUES + ["drop"]))


def _summary(finished_run, case) -> None:
    top, key, value = case
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run"
        shutil.copytree(finished_run, run)
        s = json.loads((run / "summary.json").read_text())
        table = s if top else s["designs"][0]
        if value == "drop":
            table.pop(key, None)
        else:
            table[key] = value
        (run / "summary.json").write_text(json.dumps(s))
        check(runner.invoke(app, ["inspect", str(run)]))


@QUICK
@given(summary_cases())
def test_fuzz_summary_fields_read_back_by_inspect(finished_run, case):
    _summary(finished_run, case)


@pytest.mark.fuzz
@LONG
@given(summary_cases())
def test_fuzz_summary_fields_long(finished_run, case):
    _summary(finished_run, case)
