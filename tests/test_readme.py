"""What README.md and the docs tell a user to type: the run directories its commands make, and
install commands that work."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

from swarmcode_torch.app.files import run_dir_name
from swarmcode_torch.app.session import resolve_config

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
#: What a user reads: the README, the docs, the notebooks, the benchmarks' notes, the package.
READ = [
    README,
    *sorted((ROOT / "docs").glob("*.md")),
    *sorted((ROOT / "docs").glob("*/*.md")),
    *sorted((ROOT / "notebooks").glob("*.ipynb")),
    ROOT / "benchmarks" / "README.md",
    *sorted((ROOT / "swarmcode_torch").rglob("*.py")),
    *sorted((ROOT / "examples").glob("*.py")),
]


def _first_evolve() -> list[str]:
    for line in README.read_text().splitlines():
        if "swarmcode-torch evolve " in line:
            words = shlex.split(line.split("swarmcode-torch evolve ", 1)[1])
            return words[
                : next((i for i, w in enumerate(words) if w in ("&&", "#", "|")), len(words))
            ]
    raise AssertionError("README.md has no swarmcode-torch evolve command")


def test_readme_names_the_run_directory_its_first_command_makes():
    words = _first_evolve()
    options = dict(zip(words[::2], words[1::2]))
    kinds = {
        "--scenario": str,
        "--budget": float,
        "--generations": int,
        "--population": int,
        "--seed": int,
    }
    assert set(options) <= set(kinds), options
    cfg = resolve_config(None, None, **{k[2:]: kinds[k](v) for k, v in options.items()})
    made = run_dir_name(cfg, when=0).rsplit("__", 1)[0]  # less the time
    named = re.findall(r"runs/([\w.-]+?)__<time>", README.read_text())
    assert named, "README.md names no run directory"
    assert set(named) == {made}, (named, made)


def test_readme_example_names_have_the_codes_form():
    text = README.read_text()
    examples = re.findall(r"`((?:[\w.-]+__)+\d{8}-\d{6})`", text)
    assert examples
    form = re.compile(
        r"^(?P<scenario>[\w.-]+?)(__b(?P<budget>[\d.]+))?(__(?P<objective>roi))?"
        r"__(?P<seed>\d+)__\d{8}-\d{6}$"
    )
    for name in examples:
        m = form.match(name)
        assert m, name
        cfg = resolve_config(
            None,
            None,
            scenario=m["scenario"],
            budget=None if m["budget"] is None else float(m["budget"]),
            objective=m["objective"],
            seed=int(m["seed"]),
        )
        assert run_dir_name(cfg, when=0).rsplit("__", 1)[0] == name.rsplit("__", 1)[0]


def test_extras_are_installed_from_the_source_tree_not_an_index():
    # the package is not on an index: `pip install "swarmcode-torch[ray]"` finds nothing
    for path in READ:
        text = path.read_text()
        assert not re.search(r"swarmcode-torch\[\w+\]", text), path
    said = [p for p in READ if '-e ".[ray]"' in p.read_text()]
    assert README in said and ROOT / "docs" / "DISTRIBUTED.md" in said
    from swarmcode_torch.app.distributed import RAY_INSTALL

    assert 'pip install -e ".[ray]"' in RAY_INSTALL
