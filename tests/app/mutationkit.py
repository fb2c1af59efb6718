"""The random mutations of test_fuzz_run_files.py, one per file of a run directory: the
values they draw (huge integers, NaN text, deep nesting, garbage bytes, tensors of other
dtypes and shapes) and `MUTATIONS`, file name -> mutation."""

from __future__ import annotations

import csv
import io
import json
import math
import sys

import torch
from hypothesis import strategies as st
from test_fuzz import to_toml

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


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
        table = d["app"]["best"]["designs"][0]
    elif where == "best":  # the application's record, beside the algorithm's state
        table = d["app"]["best"]
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
