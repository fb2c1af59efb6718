"""Rooms that fit a screen (CONTRIBUTING.md): no Python file of the package, its tests or its
benchmarks over 500 lines, and no function over 80 lines unless a comment right above it (above
its decorators) starts with `# long:` and says why."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MAX_FILE = 500
MAX_FUNCTION = 80


def _files() -> list[Path]:
    return sorted(
        p for d in ("swarmcode_torch", "tests", "benchmarks") for p in (ROOT / d).rglob("*.py")
    )


def _long_functions(path: Path) -> list[tuple[str, int, bool]]:
    """(name, lines, has a `# long:` reason) of every function over MAX_FUNCTION lines."""
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines()
    out = []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            n = node.end_lineno - node.lineno + 1
            if n > MAX_FUNCTION:
                first = min([d.lineno for d in node.decorator_list] + [node.lineno])
                above = lines[first - 2].strip() if first >= 2 else ""
                # the reason may run over several comment lines: find its first
                k = first - 2
                while (
                    k > 0
                    and lines[k - 1].strip().startswith("#")
                    and not above.startswith("# long:")
                ):
                    k -= 1
                    above = lines[k].strip()
                out.append((node.name, n, above.startswith("# long:")))
    return out


def test_no_file_is_over_500_lines():
    big = {
        p.relative_to(ROOT).as_posix(): n
        for p in _files()
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_FILE
    }
    assert not big, big


def test_no_function_is_over_80_lines_without_a_stated_reason():
    bad = [
        f"{p.relative_to(ROOT).as_posix()}:{name} ({n} lines)"
        for p in _files()
        for name, n, reason in _long_functions(p)
        if not reason
    ]
    assert not bad, bad


def test_the_check_finds_a_long_function_and_its_reason(tmp_path):
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_FUNCTION))
    plain = tmp_path / "plain.py"
    plain.write_text(f"def f():\n{body}")
    assert _long_functions(plain) == [("f", MAX_FUNCTION + 1, False)]
    reasoned = tmp_path / "reasoned.py"
    reasoned.write_text(
        f"# long: one kernel by design\n# (a second line)\n@staticmethod\ndef g():\n{body}"
    )
    assert _long_functions(reasoned) == [("g", MAX_FUNCTION + 1, True)]
