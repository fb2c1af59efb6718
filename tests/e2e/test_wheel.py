"""The built wheel: installed into a fresh virtual environment, away from the source tree, it
imports from its own site-packages, ships its data files and runs a tiny evolution."""

import json
import os
import shutil
import subprocess
import sys
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.subprocess


def sh(*args, cwd=None, timeout=300):
    # without PYTHONPATH: nothing but the venv and the system site-packages may be imported
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    r = subprocess.run(
        [str(a) for a in args], cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env
    )
    assert r.returncode == 0, (
        f"{args} exited {r.returncode}:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    )
    return r.stdout


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(python, console script) of a venv with the wheel of this source tree installed; the
    venv sees the test interpreter's site-packages for torch and the other dependencies (no
    download)."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"  # build from a copy: no build/ or egg-info here
    src.mkdir()
    for f in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / f, src / f)
    shutil.copytree(
        ROOT / "swarmcode_torch",
        src / "swarmcode_torch",
        ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info"),
    )
    sh(
        sys.executable,
        "-m",
        "pip",
        "wheel",
        src,
        "--no-deps",
        "--no-build-isolation",
        "-q",
        "-w",
        tmp / "dist",
    )
    wheels = list((tmp / "dist").glob("swarmcode_torch-*.whl"))
    assert len(wheels) == 1, wheels
    env = tmp / "venv"
    venv.EnvBuilder(with_pip=False).create(env)
    python = env / "bin" / "python"
    # The dependencies (torch, ...) are those of the interpreter running the tests, which may
    # itself be a virtual environment: `system_site_packages` would give the base interpreter's
    # instead. A .pth file puts this interpreter's site-packages after the new venv's own, as
    # plain paths (their .pth files, such as this source tree's editable install, are not run).
    own = sh(python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])").strip()
    outer = [p for p in sys.path if p.endswith("site-packages") and Path(p).is_dir()]
    (Path(own) / "outer-site-packages.pth").write_text("\n".join(outer) + "\n")
    sh(sys.executable, "-m", "pip", "--python", python, "install", "--no-deps", "-q", wheels[0])
    return python, env / "bin" / "swarmcode-torch", tmp


def test_wheel_imports_from_its_own_site_packages(installed):
    python, _, tmp = installed
    work = tmp / "elsewhere"
    work.mkdir(exist_ok=True)
    code = (
        "import importlib.metadata as md, json, swarmcode_torch as sc; "
        "from importlib import resources; "
        "files = resources.files('swarmcode_torch'); "
        "print(json.dumps([sc.__file__, sc.__version__, md.version('swarmcode-torch'), "
        "files.joinpath('data/hardware.toml').is_file(), "
        "files.joinpath('py.typed').is_file(), "
        "sorted(f.name for f in files.joinpath('scenarios').iterdir())]))"
    )
    path, version, dist_version, hardware, typed, scenarios = json.loads(
        sh(python, "-c", code, cwd=work)
    )
    site = (tmp / "venv").resolve()
    assert Path(path).resolve().is_relative_to(site), path  # not the editable /work tree
    assert not Path(path).resolve().is_relative_to(ROOT)
    assert version == dist_version
    assert hardware
    assert typed  # PEP 561: type checkers read its annotations
    assert {"one-niche.toml", "budget.toml", "four-niche.toml"} <= set(scenarios)


def test_wheel_console_script_evolves(installed):
    _, script, tmp = installed
    work = tmp / "work"
    work.mkdir(exist_ok=True)
    out = sh(
        script,
        "evolve",
        "--scenario",
        "one-niche",
        "--population",
        4,
        "--swarm-size",
        3,
        "--trials",
        1,
        "--ticks",
        5,
        "--generations",
        1,
        "--device",
        "cpu",
        "--no-compile",
        "--render-every",
        0,
        "--logdir",
        "X",
        cwd=work,
    )
    assert "Done: 1 generations" in out
    runs = list((work / "X").iterdir())
    assert len(runs) == 1
    for f in ("config.toml", "summary.json", "teams.jsonl", "checkpoint.pt"):
        assert (runs[0] / f).is_file(), f
    assert list(runs[0].glob("events.out.tfevents.*"))
    summary = json.loads((runs[0] / "summary.json").read_text())
    assert summary["generation"] == 0
    # an installed package is no checkout: no commit, but its version and torch's
    assert summary["software"]["commit"] is None
    from swarmcode_torch import __version__

    assert summary["software"]["swarmcode-torch"] == __version__
    sh(script.with_name("python"), "-m", "swarmcode_torch", "--help", cwd=work)
    # the replay page's template, script and styles are package data of the wheel
    sh(script, "replay", runs[0], "--html", "--ticks", 5, cwd=work)
    page = (runs[0] / "team.html").read_text()
    assert (
        'id="episode-data"' in page and "DecompressionStream" in page and "/*SCRIPT*/" not in page
    )
