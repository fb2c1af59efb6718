"""The layers are enforced: the import-linter contract of pyproject.toml ("app | baselines over
coevo over sim") holds for the package, and it does catch an import that breaks it; the tests
keep the same walls: tests/sim imports only swarmcode_torch.sim, tests/coevo only sim and coevo
(with the helpers of tests/ they import, followed through)."""

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINT = shutil.which("lint-imports") or str(Path(sys.executable).parent / "lint-imports")

needs_lint = pytest.mark.skipif(not Path(LINT).exists(), reason="import-linter is not installed")


def lint(cwd: Path, pythonpath: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(pythonpath)}
    return subprocess.run(
        [LINT, "--no-cache"], cwd=cwd, env=env, capture_output=True, text=True, timeout=300
    )


@pytest.mark.subprocess
@needs_lint
def test_the_package_keeps_its_layers():
    r = lint(ROOT, ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "2 kept, 0 broken" in r.stdout


@needs_lint
@pytest.mark.parametrize(
    "module, line, broken",
    [
        (
            "sim/hardware.py",
            "from ..coevo import population",
            "swarmcode_torch.sim is not allowed to import swarmcode_torch.coevo",
        ),
        (
            "coevo/evolve.py",
            "from ..app import runs",
            "swarmcode_torch.coevo is not allowed to import swarmcode_torch.app",
        ),
        (
            "baselines/__init__.py",
            "from ..app import records",
            "swarmcode_torch.baselines is not allowed to import swarmcode_torch.app",
        ),
    ],
)
@pytest.mark.subprocess
def test_an_import_across_the_layers_breaks_the_contract(tmp_path, module, line, broken):
    shutil.copytree(
        ROOT / "swarmcode_torch",
        tmp_path / "swarmcode_torch",
        ignore=shutil.ignore_patterns("__pycache__"),
    )
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    with open(tmp_path / "swarmcode_torch" / module, "a") as f:
        f.write(f"\n{line}  # noqa\n")
    r = lint(tmp_path, tmp_path)
    # an import up the layers may close a cycle between the packages as well
    assert r.returncode != 0 and "app | baselines over coevo over sim BROKEN" in r.stdout, (
        r.stdout + r.stderr
    )
    assert broken in r.stdout


@needs_lint
@pytest.mark.subprocess
def test_an_import_cycle_inside_a_layer_breaks_the_contract(tmp_path):
    """A lazy import inside a function closes a cycle as well as one at the top of a file."""
    shutil.copytree(
        ROOT / "swarmcode_torch",
        tmp_path / "swarmcode_torch",
        ignore=shutil.ignore_patterns("__pycache__"),
    )
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    with open(tmp_path / "swarmcode_torch/coevo/population.py", "a") as f:
        f.write("\n\ndef _late():\n    from . import speciation  # noqa\n")
    r = lint(tmp_path, tmp_path)
    assert r.returncode != 0 and "1 kept, 1 broken" in r.stdout, r.stdout + r.stderr
    assert "No cycles are allowed in swarmcode_torch.coevo" in r.stdout


# ====================================================================== the tests' own layers
TESTS = Path(__file__).resolve().parent
# a test folder -> the package's subpackages its tests (and the helpers they use) may import
ALLOWED = {"sim": ("sim",), "coevo": ("sim", "coevo")}


def _imported(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, dotted name) of every import in `tree`, at any depth; `from a import b` gives
    `a.b` (b may be a module or a name in a: both are checked against a's layer)."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out += [(node.lineno, f"{node.module}.{a.name}") for a in node.names]
    return out


def _allowed(name: str, layers: tuple[str, ...]) -> bool:
    parts = name.split(".")
    if parts[0] != "swarmcode_torch":
        return True  # not the package: torch, pytest, ...
    return len(parts) > 1 and parts[1] in layers  # bare `swarmcode_torch` loads the app


def layer_violations(tests: Path) -> list[str]:
    """'FILE:LINE imports NAME' for each import of a test under tests/sim or tests/coevo (or of
    a helper module of `tests` that such a test imports, however indirectly) that reaches above
    the folder's layer."""
    local = {p.stem: p for p in tests.rglob("*.py")}  # helpers and test modules, by name
    found = []
    for folder, layers in ALLOWED.items():
        for test in sorted((tests / folder).rglob("*.py")):
            todo, seen = [(test, [])], set()
            while todo:
                path, via = todo.pop()
                if path in seen:
                    continue
                seen.add(path)
                for line, name in _imported(ast.parse(path.read_text(), str(path))):
                    top = name.split(".")[0]
                    if top in local and local[top] != path:
                        todo.append((local[top], via + [f"{path.relative_to(tests)}:{line}"]))
                    elif not _allowed(name, layers):
                        chain = " via ".join([f"{path.relative_to(tests)}:{line}"] + via[::-1])
                        found.append(
                            f"tests/{chain} imports {name} (tests/{folder} may import "
                            f"only {', '.join('swarmcode_torch.' + x for x in layers)})"
                        )
    return found


def test_tests_of_a_layer_import_nothing_above_it():
    assert (TESTS / "sim").is_dir() and (TESTS / "coevo").is_dir()
    assert layer_violations(TESTS) == []


def test_the_check_names_the_file_and_the_import(tmp_path):
    (tmp_path / "sim").mkdir()
    (tmp_path / "coevo").mkdir()
    (tmp_path / "kit.py").write_text("from swarmcode_torch.coevo.population import R_MAX\n")
    (tmp_path / "sim" / "test_a.py").write_text(
        "import torch\nfrom swarmcode_torch.sim import bt\n\n"
        "def test_x():\n    from swarmcode_torch.coevo import evolve\n"
    )
    (tmp_path / "sim" / "test_b.py").write_text("import kit\n")
    (tmp_path / "coevo" / "test_c.py").write_text(
        "from swarmcode_torch.coevo import evolve\nimport kit\nimport swarmcode_torch as sc\n"
        "from swarmcode_torch import app\n"
    )
    assert layer_violations(tmp_path) == [
        "tests/sim/test_a.py:5 imports swarmcode_torch.coevo.evolve "
        "(tests/sim may import only swarmcode_torch.sim)",
        "tests/kit.py:1 via sim/test_b.py:1 imports swarmcode_torch.coevo.population.R_MAX "
        "(tests/sim may import only swarmcode_torch.sim)",
        "tests/coevo/test_c.py:3 imports swarmcode_torch "
        "(tests/coevo may import only swarmcode_torch.sim, swarmcode_torch.coevo)",
        "tests/coevo/test_c.py:4 imports swarmcode_torch.app "
        "(tests/coevo may import only swarmcode_torch.sim, swarmcode_torch.coevo)",
    ]
