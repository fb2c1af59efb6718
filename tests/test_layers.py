"""The layers are enforced: the import-linter contract of pyproject.toml ("app | baselines over
coevo over sim") holds for the package, and it does catch an import that breaks it."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINT = shutil.which("lint-imports") or str(Path(sys.executable).parent / "lint-imports")

pytestmark = pytest.mark.skipif(not Path(LINT).exists(), reason="import-linter is not installed")


def lint(cwd: Path, pythonpath: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(pythonpath)}
    return subprocess.run([LINT, "--no-cache"], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=300)


def test_the_package_keeps_its_layers():
    r = lint(ROOT, ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "1 kept, 0 broken" in r.stdout


@pytest.mark.parametrize("module, line, broken", [
    ("sim/hardware.py", "from ..coevo import population", "swarmcode_torch.sim is not allowed to import swarmcode_torch.coevo"),
    ("coevo/evolve.py", "from ..app import runs", "swarmcode_torch.coevo is not allowed to import swarmcode_torch.app"),
    ("baselines/__init__.py", "from ..app import records", "swarmcode_torch.baselines is not allowed to import swarmcode_torch.app"),
])
def test_an_import_across_the_layers_breaks_the_contract(tmp_path, module, line, broken):
    shutil.copytree(ROOT / "swarmcode_torch", tmp_path / "swarmcode_torch",
                    ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    with open(tmp_path / "swarmcode_torch" / module, "a") as f:
        f.write(f"\n{line}  # noqa\n")
    r = lint(tmp_path, tmp_path)
    assert r.returncode != 0 and "0 kept, 1 broken" in r.stdout, r.stdout + r.stderr
    assert broken in r.stdout
