"""Fuzzing the files of a run directory (issue 39): summary.json, teams.jsonl, metrics.csv,
config.toml and checkpoint.pt of a tiny finished run are mutated at random (a value at any
depth replaced by another of any type, a field deleted, lines and rows dropped, duplicated,
reordered or garbage, cells and header cells edited, byte garbage, a checkpoint entry replaced by
another value or a tensor of another dtype or shape), and every command that reads the file
(`inspect`, `dynamics`, `replay` GIF and page, `evolve --resume`) runs on the copy. Each case
ends with exit 0 or a one-line error naming the file (no traceback), within 60 s, and the run's
files unchanged; a resume that succeeds keeps the records of the generations before its
checkpoint.

The default run is small and deterministic (derandomize=True); `pytest -m fuzz` runs the same
properties with many more random examples.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import shutil
import signal
import sys
import tempfile
from pathlib import Path

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_fuzz import to_toml
from typer.testing import CliRunner

from swarmcode_torch.app.cli import app

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

runner = CliRunner()
QUICK = settings(
    max_examples=15,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=list(HealthCheck),
)
LONG = settings(
    max_examples=200, deadline=None, database=None, suppress_health_check=list(HealthCheck)
)
#: The seconds one command may take on a mutated run before the case counts as a hang.
HANG_S = 60
RUN = [
    "--scenario",
    "one-niche",
    "--population",
    "6",
    "--swarm-size",
    "3",
    "--trials",
    "1",
    "--ticks",
    "6",
    "--generations",
    "3",
    "--checkpoint-every",
    "1",
    "--render-every",
    "0",
    "--no-compile",
    "--device",
    "cpu",
]
#: The commands a case runs: (name, arguments after the run directory's place is filled).
COMMANDS = {
    "inspect": ["inspect", "{run}"],
    "dynamics": ["dynamics", "{run}"],
    "replay": ["replay", "{run}", "--ticks", "3", "--out", "{out}/team.gif"],
    "replay-html": ["replay", "{run}", "--ticks", "3", "--html", "--out", "{out}/team.html"],
    "replay-generation": [
        "replay",
        "{run}",
        "--generation",
        "1",
        "--ticks",
        "3",
        "--out",
        "{out}/g1.gif",
    ],
    "resume": ["evolve", "--resume", "{run}", "--generations", "4", "--render-every", "0"],
}
#: The commands that read each file (a resume reads them all).
READERS = {
    "summary.json": ["inspect", "replay", "replay-html", "resume"],
    "teams.jsonl": ["inspect", "replay-generation", "dynamics", "resume"],
    "metrics.csv": ["inspect", "dynamics", "resume"],
    "config.toml": ["inspect", "dynamics", "replay", "replay-html", "resume"],
    "checkpoint.pt": ["inspect", "dynamics", "replay", "resume"],
}


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    logdir = tmp_path_factory.mktemp("fuzzfiles")
    r = runner.invoke(app, ["evolve", *RUN, "--logdir", str(logdir)])
    assert r.exit_code == 0, r.output
    (run,) = list(logdir.iterdir())
    return run


# ------------------------------------------------------------------ values
HUGE_INTS = st.sampled_from([2**31, 2**63 - 1, 2**63, 2**64, -(2**63) - 1, 10**30, 10**400])
#: Stands for an integer of 5,000 digits, more than Python converts to or from text by default
#: (Hypothesis could not print the value itself): `_dumps` writes it as that number, a
#: checkpoint mutation stores the integer.
HUGE = "<10**5000>"
FLOAT_TEXT = st.sampled_from(["nan", "NaN", "inf", "-inf", "Infinity", "1e999", "-0", ""])
SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-10, 10**6),
    HUGE_INTS,
    st.floats(allow_nan=True, allow_infinity=True),
    FLOAT_TEXT,
    st.just(HUGE),
    st.text(max_size=12),
    st.text(min_size=300, max_size=400),
)


def _nested(depth: int):
    v: object = 0
    for i in range(depth):
        v = [v] if i % 2 else {"x": v}
    return v


#: Any JSON value: scalars, lists and tables of them, and values nested 10 to 200 levels deep.
JSON_VALUES = st.one_of(
    st.recursive(
        SCALARS,
        lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner),
        max_leaves=8,
    ),
    st.integers(10, 200).map(_nested),
)


def _paths(v, at=()) -> list[tuple]:
    """Every place inside a JSON value (the keys and indices leading to it)."""
    out = [at]
    if isinstance(v, dict):
        for k, x in v.items():
            out += _paths(x, (*at, k))
    elif isinstance(v, list):
        for i, x in enumerate(v):
            out += _paths(x, (*at, i))
    return out


def _mutate_json(draw, doc):
    """`doc` with one value at any depth replaced by any JSON value, deleted (from its table or
    list) or duplicated (in its list); the whole document replaced now and then."""
    places = _paths(doc)
    where = draw(st.sampled_from(places))
    op = draw(st.sampled_from(["replace", "replace", "replace", "delete", "duplicate"]))
    if not where:
        return draw(JSON_VALUES) if op == "replace" else doc
    parent = doc
    for k in where[:-1]:
        parent = parent[k]
    key = where[-1]
    if op == "replace":
        parent[key] = draw(JSON_VALUES)
    elif op == "delete":
        del parent[key]
    elif isinstance(parent, list):
        parent.insert(key, parent[key])
    return doc


def _dumps(v) -> str:
    return json.dumps(v, allow_nan=True).replace(json.dumps(HUGE), "1" + "0" * 5000)


def _huge(v):
    """`v` with every HUGE replaced by the integer it stands for."""
    if v == HUGE:
        return 10**5000
    if isinstance(v, list):
        return [_huge(x) for x in v]
    if isinstance(v, dict):
        return {k: _huge(x) for k, x in v.items()}
    return v


GARBAGE = st.one_of(
    st.binary(max_size=40),
    st.sampled_from([b"", b"\x00", b"\xff\xfe", b"[", b"{", b'"', b"nan", b"\x1b[31m", b"\r"]),
    st.text(max_size=40).map(lambda s: s.encode("utf-8", "surrogatepass")),
)


# ------------------------------------------------------------------ mutations, one per file
def summary_mutation(draw, data: bytes) -> bytes:
    return _dumps(_mutate_json(draw, json.loads(data))).encode()


def teams_mutation(draw, data: bytes) -> bytes:
    lines = data.splitlines(keepends=True)
    op = draw(st.sampled_from(["json", "json", "drop", "duplicate", "swap", "garbage", "cut"]))
    i = draw(st.integers(0, len(lines) - 1))
    if op == "json":
        lines[i] = (_dumps(_mutate_json(draw, json.loads(lines[i]))) + "\n").encode()
    elif op == "drop":
        del lines[i]
    elif op == "duplicate":
        lines.insert(draw(st.integers(0, len(lines))), lines[i])
    elif op == "swap":
        j = draw(st.integers(0, len(lines) - 1))
        lines[i], lines[j] = lines[j], lines[i]
    elif op == "garbage":
        lines.insert(i, draw(GARBAGE) + b"\n")
    else:  # the last line cut short
        lines[-1] = lines[-1][: draw(st.integers(0, len(lines[-1]) - 1))]
    return b"".join(lines)


CELLS = st.one_of(
    FLOAT_TEXT,
    st.sampled_from(["abc", "-1", "0", "1.5", "99", str(10**30), "1e308", '"', "a,b", "x\ny"]),
    st.integers(-5, 5).map(str),
    st.text(max_size=10),
)


def metrics_mutation(draw, data: bytes) -> bytes:
    rows = list(csv.reader(io.StringIO(data.decode(), newline="")))
    op = draw(
        st.sampled_from(
            ["cell", "cell", "add", "remove", "header", "drop", "duplicate", "swap", "bytes"]
        )
    )
    i = draw(st.integers(0, len(rows) - 1))
    j = draw(st.integers(0, len(rows[i]) - 1))
    if op == "cell":
        rows[i][j] = draw(CELLS)
    elif op == "add":
        rows[i].insert(j, draw(CELLS))
    elif op == "remove":
        del rows[i][j]
    elif op == "header":
        rows[0][j] = draw(st.sampled_from(rows[0] + ["", "generation", "x"]) | CELLS)
    elif op == "drop":
        del rows[i]
    elif op == "duplicate":
        rows.insert(draw(st.integers(0, len(rows))), rows[i])
    elif op == "swap":
        k = draw(st.integers(0, len(rows) - 1))
        rows[i], rows[k] = rows[k], rows[i]
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    out = buf.getvalue().encode()
    if op == "bytes":
        at = draw(st.integers(0, len(out)))
        out = out[:at] + draw(GARBAGE) + out[at:]
    return out


#: TOML values of every type (TOML has no null; its integers are 64-bit, so 2**64 is a parse
#: error the reader must name).
TOML_VALUES = st.one_of(
    st.booleans(),
    st.integers(-10, 10**6),
    st.sampled_from([2**63 - 1, -(2**63)]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(["none", "", "x", "cpu", "cuda", "default", "fitness", "all", "one-niche"]),
    st.text(max_size=10),
    st.lists(st.integers(-3, 3), max_size=3),
    st.dictionaries(st.sampled_from(["a", "b"]), st.integers(0, 3), max_size=2),
)


def config_mutation(draw, data: bytes) -> bytes:
    d = tomllib.loads(data.decode())
    op = draw(st.sampled_from(["replace", "replace", "replace", "delete", "unknown", "bytes"]))
    key = draw(st.sampled_from(sorted(d)))
    if op == "replace":
        d[key] = draw(TOML_VALUES)
    elif op == "delete":
        del d[key]
    elif op == "unknown":
        d[draw(st.sampled_from(["x", "w_unknown", "parent", "Seed"]))] = draw(TOML_VALUES)
    out = to_toml(d).encode()
    if op == "bytes":
        at = draw(st.integers(0, len(out)))
        out = out[:at] + draw(GARBAGE) + out[at:]
    return out


DTYPES = [torch.float32, torch.float64, torch.float16, torch.int64, torch.int8, torch.uint8]
DTYPES += [torch.bool, torch.complex64]


@st.composite
def tensors(draw, like=None):
    """A tensor of another dtype or shape than `like` (the entry it replaces), or any tensor."""
    dtype = draw(st.sampled_from(DTYPES))
    if like is not None and draw(st.booleans()):
        t = like.to(dtype) if dtype != torch.complex64 else like.to(torch.float32).to(dtype)
        op = draw(st.sampled_from(["same", "flat", "slice", "extend"]))
        if op == "flat":
            t = t.reshape(-1)
        elif op == "slice" and t.dim() and t.shape[0]:
            t = t[: draw(st.integers(0, t.shape[0] - 1))]
        elif op == "extend":
            t = torch.cat([t, t]) if t.dim() else t.reshape(1, 1)
        return t.clone()
    shape = draw(st.sampled_from([(), (0,), (1,), (6,), (3,), (6, 1), (2, 3), (6, 32), (7,)]))
    fill = draw(st.sampled_from([0, 1, -1, 99, 10**6, math.nan, math.inf]))
    if dtype in (torch.int8, torch.uint8, torch.int64, torch.bool) and not (
        isinstance(fill, int) and -128 <= fill <= 127
    ):
        fill = 1
    if dtype == torch.uint8 and fill < 0:
        fill = 0
    return torch.full(shape, fill, dtype=dtype)


def checkpoint_mutation(draw, data: bytes) -> bytes:
    d = torch.load(io.BytesIO(data), weights_only=True)
    where = draw(
        st.sampled_from(
            ["top", "top", "best", "history", "admission", "genome", "config", "designs"]
        )
    )
    if where == "top":
        table = d
    elif where == "history":
        table = d["history"][draw(st.integers(0, len(d["history"]) - 1))]
    elif where == "designs":
        table = d["best"]["designs"][0]
    else:
        table = d[where]
    key = draw(st.sampled_from(sorted(table)))
    old = table[key]
    op = draw(st.sampled_from(["value", "tensor", "delete"]))
    if op == "delete":
        del table[key]
    elif op == "tensor":
        table[key] = draw(tensors(old if isinstance(old, torch.Tensor) else None))
    else:
        table[key] = _huge(draw(JSON_VALUES))
    buf = io.BytesIO()
    torch.save(d, buf)
    return buf.getvalue()


MUTATIONS = {
    "summary.json": summary_mutation,
    "teams.jsonl": teams_mutation,
    "metrics.csv": metrics_mutation,
    "config.toml": config_mutation,
    "checkpoint.pt": checkpoint_mutation,
}
CASES = [(f, c) for f, cs in READERS.items() for c in cs]


# ------------------------------------------------------------------ the property
def _files(run: Path) -> dict[str, bytes]:
    return {
        str(f.relative_to(run)): f.read_bytes()
        for f in sorted(run.rglob("*"))
        if f.is_file() and not f.is_symlink()
    }


@contextlib.contextmanager
def _time_guard(seconds: int):
    """A TimeoutError in the command after `seconds` (a hang is a failed case, not a stuck
    test run)."""

    def stop(signum, frame):
        raise TimeoutError(f"no answer within {seconds} s")

    old = signal.signal(signal.SIGALRM, stop)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def one_line_or_success(result, name: str) -> None:
    """exit 0, or a one-line error naming the file `name`; never a traceback."""
    assert "Traceback" not in result.output, result.output[-3000:]
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(
        result.exception
    )
    if result.exit_code != 0:
        lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1, result.output[-3000:]
        assert lines[0].startswith("Error: "), result.output[-3000:]
        assert name in lines[0], lines[0]


def _kept_teams(before: bytes, generation: int) -> bytes:
    """The lines of teams.jsonl a resume from a checkpoint of `generation` keeps: every complete
    line but the records of generations it computes again."""
    keep = []
    for line in before.splitlines(keepends=True):
        if not line.endswith(b"\n"):
            continue  # a cut-off last line: set aside in teams.jsonl.partial
        try:
            rec = json.loads(line)
        except (ValueError, RecursionError):
            rec = None
        g = rec.get("generation") if isinstance(rec, dict) else None
        if not (isinstance(g, int) and not isinstance(g, bool) and g >= generation):
            keep.append(line)
    return b"".join(keep)


def _metric_rows(data: bytes, below: int) -> list[dict]:
    rows = csv.DictReader(io.StringIO(data.decode(), newline=""))
    return [r for r in rows if int(r["generation"]) < below]


def _check_resume_kept_records(before: dict, after: dict, generation: int) -> None:
    for name in ("scenario.toml", "hardware.toml"):
        assert after.get(name) == before.get(name), name
    if "teams.jsonl" in before:
        assert after["teams.jsonl"].startswith(_kept_teams(before["teams.jsonl"], generation))
    if "metrics.csv" in before:
        old = _metric_rows(before["metrics.csv"], generation)
        new = _metric_rows(after["metrics.csv"], generation)
        assert [{k: r.get(k) for k in o} for o, r in zip(old, new)] == old
        assert len(new) == len(old)


def _case(finished_run: Path, name: str, command: str, mutate) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        run, out = Path(tmp) / "run", Path(tmp) / "out"
        shutil.copytree(finished_run, run)
        out.mkdir()
        path = run / name
        path.write_bytes(mutate(path.read_bytes()))
        before = _files(run)
        args = [a.format(run=run, out=out) for a in COMMANDS[command]]
        with _time_guard(HANG_S):
            result = runner.invoke(app, args)
        one_line_or_success(result, name)
        after = _files(run)
        if command == "resume" and result.exit_code == 0:
            generation = torch.load(io.BytesIO(before["checkpoint.pt"]), weights_only=True)[
                "generation"
            ]
            _check_resume_kept_records(before, after, generation)
        else:
            assert after == before, sorted(k for k in after if after.get(k) != before.get(k))


@pytest.mark.parametrize("name,command", CASES)
@QUICK
@given(data=st.data())
def test_fuzz_run_files(finished_run, name, command, data):
    _case(finished_run, name, command, lambda b: MUTATIONS[name](data.draw, b))


@pytest.mark.fuzz
@pytest.mark.parametrize("name,command", CASES)
@LONG
@given(data=st.data())
def test_fuzz_run_files_long(finished_run, name, command, data):
    _case(finished_run, name, command, lambda b: MUTATIONS[name](data.draw, b))


# ------------------------------------------------------------------ what the fuzzing found
def _json_edit(edit):
    def mutate(data: bytes) -> bytes:
        d = json.loads(data)
        edit(d)
        return json.dumps(d).encode()

    return mutate


def _design(key, value):
    def edit(d):
        d["designs"][0][key] = value

    return _json_edit(edit)


def _checkpoint_edit(edit):
    def mutate(data: bytes) -> bytes:
        d = torch.load(io.BytesIO(data), weights_only=True)
        edit(d)
        buf = io.BytesIO()
        torch.save(d, buf)
        return buf.getvalue()

    return mutate


def _teams_huge_line(data: bytes) -> bytes:
    return data + b'{"generation": 1' + b"0" * 5000 + b"}\n"


FOUND = [
    # a design's selectivity was not checked: float() of a list in the replay
    ("summary.json", "replay", _design("selectivity", {"x": [0]}), "designs[0].selectivity"),
    # a tier compared with `in (1, 2, 3)`: a tensor's truth value in dynamics and resume
    (
        "checkpoint.pt",
        "dynamics",
        _checkpoint_edit(
            lambda d: d["best"]["designs"][0].__setitem__("battery_tier", torch.tensor([]))
        ),
        "best: designs[0].battery_tier",
    ),
    # an integer of 5,000 digits: ValueError from json.loads and from every repr of it
    ("summary.json", "inspect", lambda b: b"1" + b"0" * 5000, "more than 4300 digits"),
    ("teams.jsonl", "replay-generation", _teams_huge_line, "more than 4300 digits"),
    (
        "checkpoint.pt",
        "dynamics",
        _checkpoint_edit(lambda d: d["best"]["designs"][0].__setitem__("radius", 10**400)),
        "best: designs[0].radius",
    ),
    # an integer too large for a float: OverflowError from math.isfinite
    ("summary.json", "inspect", _design("radius", 10**400), "designs[0].radius"),
    ("summary.json", "replay-html", _design("cost", -(10**400)), "designs[0].cost"),
    (
        "summary.json",
        "inspect",
        _json_edit(lambda d: d.update(best_fitness=10**400)),
        "best_fitness",
    ),
    # checkpoint records that passed its checks and broke the resume: a best fitness too
    # large for a float (OverflowError) and a population count beyond int64 (TypeError)
    (
        "checkpoint.pt",
        "resume",
        _checkpoint_edit(lambda d: d["best"].__setitem__("fitness", 10**400)),
        "best.fitness",
    ),
    (
        "checkpoint.pt",
        "resume",
        _checkpoint_edit(lambda d: d["history"][1]["population"].__setitem__(3, 10**400)),
        "history[1].population",
    ),
    # a best fitness of NaN was resumed from (no later team compares above it)
    (
        "checkpoint.pt",
        "resume",
        _checkpoint_edit(lambda d: d["best"].__setitem__("fitness", math.nan)),
        "best.fitness",
    ),
]


@pytest.mark.parametrize(
    "name,command,mutate,needle",
    FOUND,
    ids=[
        "selectivity-table",
        "tier-empty-tensor",
        "summary-5000-digits",
        "teams-5000-digits",
        "checkpoint-radius-10e400",
        "radius-10e400",
        "cost-minus-10e400",
        "best-fitness-10e400",
        "checkpoint-best-fitness-10e400",
        "checkpoint-population-count-10e400",
        "checkpoint-best-fitness-nan",
    ],
)
def test_what_the_fuzzing_found_is_one_line(finished_run, name, command, mutate, needle):
    with tempfile.TemporaryDirectory() as tmp:
        run, out = Path(tmp) / "run", Path(tmp) / "out"
        shutil.copytree(finished_run, run)
        out.mkdir()
        (run / name).write_bytes(mutate((run / name).read_bytes()))
        before = _files(run)
        with _time_guard(HANG_S):
            result = runner.invoke(app, [a.format(run=run, out=out) for a in COMMANDS[command]])
        assert result.exit_code == 2, result.output[-3000:]
        one_line_or_success(result, name)
        assert needle in result.stderr, result.stderr
        assert _files(run) == before
