"""The documentation site (mkdocs.yml, docs/, docs/hooks.py): every public name of
swarmcode_torch has its API reference entry, every page and notebook is in the navigation, the
file formats cover every key the loaders accept, the site builds with --strict, and links to
repository files outside the site work while a broken link still fails the build.

The tests that build need the `docs` extra (mkdocs and its plugins; .ci/run installs it)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import swarmcode_torch

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
HOOKS = DOCS / "hooks.py"


def _nav_files() -> list[str]:
    """Every file the nav of mkdocs.yml names (read as text: `- Title: path`)."""
    text = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    nav = text[text.index("\nnav:") :]
    return re.findall(r"^\s*- (?:[^:\n]+:\s+)?([\w./-]+\.(?:md|ipynb))\s*$", nav, re.M)


def _directives() -> dict[str, str]:
    """`::: swarmcode_torch.NAME` directives of docs/reference/*.md: object path -> page."""
    out = {}
    for page in sorted((DOCS / "reference").glob("*.md")):
        for name in re.findall(r"^::: ([\w.]+)\s*$", page.read_text(encoding="utf-8"), re.M):
            out[name] = page.relative_to(DOCS).as_posix()
    return out


def test_every_public_name_has_a_reference_entry():
    documented = {
        name.split(".", 1)[1]
        for name in _directives()
        if name.count(".") == 1 and name.startswith("swarmcode_torch.")
    }
    missing = sorted(set(swarmcode_torch.__all__) - documented)
    assert not missing, (
        f"public names without a `::: swarmcode_torch.NAME` in docs/reference: {missing}"
    )


def test_every_page_and_notebook_is_in_the_nav_and_every_nav_entry_exists():
    nav = _nav_files()
    assert len(nav) == len(set(nav)), "a page is twice in the nav"
    pages = {
        p.relative_to(DOCS).as_posix()
        for p in DOCS.rglob("*.md")
        if not p.relative_to(DOCS).as_posix().startswith("results/")
    }
    notebooks = {p.relative_to(ROOT).as_posix() for p in (ROOT / "notebooks").glob("*.ipynb")}
    assert len(notebooks) == 3
    assert pages | notebooks | {"CHANGELOG.md"} == set(nav)
    for entry in nav:
        assert (DOCS / entry).is_file() or (ROOT / entry).is_file(), entry
    for ref in set(_directives().values()):
        assert ref in nav


def _accepted_scenario_keys() -> set[str]:
    """Every key the scenario loader accepts: the sets it checks keys against
    (`sim.scenario`: FIELDS at the top level, OBSTACLE_FIELDS, PACKAGE_FIELDS)."""
    from swarmcode_torch.sim import scenario

    return {*scenario.FIELDS, *scenario.OBSTACLE_FIELDS, *scenario.PACKAGE_FIELDS}


def test_scenario_format_page_documents_every_accepted_key():
    keys = _accepted_scenario_keys()
    # the sets found are the loader's: what every built-in scenario uses is among them
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    used = set()
    for f in (ROOT / "swarmcode_torch/scenarios").glob("*.toml"):
        d = tomllib.loads(f.read_text(encoding="utf-8"))
        used |= set(d) | set(d.get("obstacles", {})) | {k for p in d["packages"] for k in p}
    assert used <= keys and {"grips", "size", "radius_band", "hardware"} <= keys
    page = (DOCS / "formats/scenario.md").read_text(encoding="utf-8")
    table_keys = set(re.findall(r"^\| `(\w+)` \|", page, re.M))
    assert keys <= table_keys, (
        f"not in docs/formats/scenario.md's tables: {sorted(keys - table_keys)}"
    )


def _build(config: Path, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config), "-d", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=config.parent,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1", "PYTHONPATH": str(ROOT)},
    )


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings_handlers.python")
    pytest.importorskip("mkdocs_jupyter")
    pytest.importorskip("material")
    out = tmp_path_factory.mktemp("site")
    r = _build(ROOT / "mkdocs.yml", out)
    assert r.returncode == 0, r.stdout + r.stderr
    return out


def test_every_link_of_the_site_opens_from_disk(site):
    """A site opened as files (file://) has no server to turn a folder into its index.html:
    every relative link of every page leads to a file that exists, never a folder."""
    checked = 0
    for page in site.rglob("*.html"):
        for href in re.findall(r'href="([^"#?]*)[^"]*"', page.read_text(encoding="utf-8")):
            if not href or re.match(r"[a-z]+:|//", href):
                continue
            target = (page.parent / href).resolve()
            if site.resolve() not in target.parents:  # a repository file beside the site
                continue
            assert target.is_file(), f"{page.relative_to(site)} links to {href}"
            checked += 1
    assert checked > 100


def _text(path: Path) -> str:
    import html

    return html.unescape(re.sub(r"<[^>]+>", "", path.read_text(encoding="utf-8")))


@pytest.mark.subprocess
def test_site_reference_has_every_public_name(site):
    html = "".join(p.read_text(encoding="utf-8") for p in (site / "reference").rglob("*.html"))
    ids = set(re.findall(r'id="swarmcode_torch\.(\w+)"', html))
    assert set(swarmcode_torch.__all__) <= ids, sorted(set(swarmcode_torch.__all__) - ids)
    # a dataclass's fields are there with their docstrings
    config = _text(site / "reference/config.html")
    for name in ("generations", "population", "delta", "quota_size_exponent"):
        assert f'id="swarmcode_torch.SwarmCoDeConfig.{name}"' in html
    assert "Total number of generations of the run." in config


@pytest.mark.subprocess
def test_site_cli_page_is_the_help_of_every_command(site):
    import typer

    from swarmcode_torch.app.cli import app

    commands = list(typer.main.get_command(app).commands)
    assert {"evolve", "sweep", "inspect", "replay", "dynamics", "scenarios"} <= set(commands)
    text = _text(site / "cli.html")
    for name in commands:
        assert f"Usage: swarmcode-torch {name} [OPTIONS]" in text, name
    # each command's summary in full, where --help cuts it to the terminal's width
    flat = " ".join(text.split())
    longest = 0
    for name, command in typer.main.get_command(app).commands.items():
        summary = " ".join((command.help or "").split("\n\n", 1)[0].split())
        assert summary in flat, name
        longest = max(longest, len(summary))
    assert longest > 80  # longer than --help's summary column
    # the options of the code as it is, e.g. evolve's
    for option in ("--scenario", "--generations", "--resume", "--set"):
        assert re.search(
            rf"^\s+{option}\b",
            text.split("Usage: swarmcode-torch evolve")[1].split("Usage: swarmcode-torch")[0],
            re.M,
        ), option


@pytest.mark.subprocess
def test_site_hardware_page_has_every_catalog_field_and_bound(site):
    from swarmcode_torch.sim import hardware as hw

    text = _text(site / "formats/hardware.html")
    rows = {
        (m.group(1), m.group(2)): m.group(0)
        for m in re.finditer(r"\[(\w+)\]\s+(\w+)\s+(.*?)\n(.*?)\n(.*?)\n", text)
    }
    assert len(hw._CATALOG_FIELDS) == 16
    for section, key, _, _, (lo, hi, lo_ok) in hw._CATALOG_FIELDS:
        assert (section, key) in rows, (section, key)
        assert f"{'[' if lo_ok else '('}{lo:g}, {hi:g}]" in rows[section, key]


def _public_functions() -> dict[str, list[str]]:
    """The public functions of swarmcode_torch with parameters -> their parameter names
    (`*args` as `*args`; a `**settings` catch-all is documented by the keys it takes)."""
    import inspect

    out = {}
    for name in swarmcode_torch.__all__:
        obj = getattr(swarmcode_torch, name)
        if not inspect.isfunction(obj):
            continue
        params = [
            ("*" if p.kind is p.VAR_POSITIONAL else "") + p.name
            for p in inspect.signature(obj).parameters.values()
            if p.kind is not p.VAR_KEYWORD
        ]
        if params:
            out[name] = params
    return out


@pytest.mark.subprocess
def test_site_reference_shows_each_functions_parameters_as_a_table(site):
    """Google-style docstrings (Args/Returns/Raises) render as tables: every parameter of every
    public function is a row of its Parameters table, with a description."""
    html = "".join(p.read_text(encoding="utf-8") for p in (site / "reference").rglob("*.html"))
    functions = _public_functions()
    assert {"evolve", "evaluate", "generate_world", "load_runs"} <= set(functions)
    for name, params in functions.items():
        start = html.index(f'id="swarmcode_torch.{name}"')
        end = html.find('<div class="doc doc-object', start)
        section = html[start : end if end > 0 else len(html)]
        assert "Parameters:</span>" in section and "<table>" in section, name
        rows = re.findall(r"<td>\s*<code>([^<]+)</code>\s*</td>", section)
        missing = [p for p in params if p not in rows]
        assert not missing, f"{name}: parameters without a row: {missing}"


@pytest.mark.subprocess
def test_site_has_the_notebooks_and_the_changelog(site):
    for nb in ("01_quickstart", "02_analyze_run", "03_budget_sweep"):
        page = site / "notebooks" / f"{nb}.html"
        assert page.is_file(), nb
    assert "import swarmcode_torch as sc" in _text(site / "notebooks/01_quickstart.html")
    # the tutorials are shown with their outputs: the progress of the run, tables, figures
    quick = (site / "notebooks/01_quickstart.html").read_text(encoding="utf-8")
    assert "done 10/10" in quick and "<table" in quick
    assert quick.count("data:image/png;base64,") >= 2
    for nb in ("02_analyze_run", "03_budget_sweep"):
        assert "data:image/png;base64," in (site / f"notebooks/{nb}.html").read_text("utf-8")
    assert "Keep a Changelog" in _text(site / "CHANGELOG.html")
    assert not (site / "results").exists()  # the data folders stay out of the site
    assert not (site / "hooks.py").exists()


# --- links to repository files: a small project of its own with the site's hooks -----------


def _project(tmp_path: Path, page: str) -> Path:
    (tmp_path / "docs/results/cpu").mkdir(parents=True)
    (tmp_path / "docs/results/cpu/table.json").write_text("{}\n")
    (tmp_path / "examples").mkdir()
    (tmp_path / "examples/world.toml").write_text("name = 'x'\n")
    (tmp_path / "docs/index.md").write_text("# Home\n\n[other](other.md)\n")
    (tmp_path / "docs/other.md").write_text(page)
    (tmp_path / "mkdocs.yml").write_text(
        "site_name: t\ndocs_dir: docs\nexclude_docs: |\n  /results/\n"
        f"hooks:\n  - {HOOKS.as_posix()}\nnav:\n  - index.md\n  - other.md\n"
    )
    return tmp_path / "mkdocs.yml"


@pytest.mark.subprocess
def test_links_to_repository_files_outside_the_site_build_and_lead_to_the_file(tmp_path):
    pytest.importorskip("mkdocs")
    page = (
        "# Other\n\n[world](../examples/world.toml), [table](results/cpu/table.json), "
        "[folder](results/cpu/), [home](index.md#home)\n\n"
        "```\n[not a link](../nowhere.md)\n```\n"
    )
    r = _build(_project(tmp_path, page), tmp_path / "site")
    assert r.returncode == 0, r.stdout + r.stderr
    built = tmp_path / "site/other/index.html"
    hrefs = re.findall(r'href="([^"]+)"', built.read_text(encoding="utf-8"))
    for target in ("examples/world.toml", "docs/results/cpu/table.json", "docs/results/cpu/"):
        href = next(h for h in hrefs if h.endswith(target))
        # relative from the built page to the file in the checkout
        assert (built.parent / href).resolve() == (tmp_path / target).resolve()
    assert any(h.endswith("#home") and not h.startswith("repo-file:") for h in hrefs)
    assert "[not a link](../nowhere.md)" in built.read_text(encoding="utf-8")
    assert not (tmp_path / "site/results").exists()


@pytest.mark.subprocess
@pytest.mark.parametrize("link", ["missing.md", "../examples/missing.toml", "results/none.json"])
def test_a_broken_link_fails_the_strict_build(tmp_path, link):
    pytest.importorskip("mkdocs")
    r = _build(_project(tmp_path, f"# Other\n\n[broken]({link})\n"), tmp_path / "site")
    assert r.returncode != 0
    assert link in r.stdout + r.stderr
