"""The type checker over the simulator and the algorithm (`[tool.mypy]` in pyproject.toml), so a
type error there fails the local suite as it fails CI. About 25 s the first time, a few seconds
once mypy's cache (.mypy_cache) is warm."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytest.importorskip("mypy", reason="mypy is not installed (pip install -e '.[dev]')")


@pytest.mark.subprocess
def test_mypy_passes_over_sim_and_coevo():
    r = subprocess.run(
        [sys.executable, "-m", "mypy"], cwd=ROOT, capture_output=True, text=True, timeout=600
    )
    assert r.returncode == 0, f"mypy found type errors:\n{r.stdout[-6000:]}\n{r.stderr[-2000:]}"
    # every module of the two packages was checked: the configured files are these folders
    modules = [p for d in ("sim", "coevo") for p in (ROOT / "swarmcode_torch" / d).rglob("*.py")]
    assert f"no issues found in {len(modules)} source files" in r.stdout, r.stdout
