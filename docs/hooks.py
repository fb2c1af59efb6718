"""Build hooks of the documentation site (mkdocs.yml `hooks:`). What they generate is made anew
at every build from the code, so that it cannot go stale:

- the tutorials: notebooks/*.ipynb, added as pages (mkdocs-jupyter renders them, without
  executing them), and CHANGELOG.md;
- the CLI reference: the `--help` of every command, in place of `<!-- cli-reference -->`;
- the keywords `swarmcode_torch.evolve` takes from the option declarations
  (`app/run_options.py`), in place of `<!-- evolve-keywords -->`;
- the hardware catalog's fields with their bounds and built-in values, in place of
  `<!-- hardware-catalog -->`;
- links to repository files that are not part of the site (`../examples/three-niche.toml`,
  `results/...`): rewritten to the file in the repository (`repo_url` in mkdocs.yml, else a
  relative link from the built page to the checkout). A link whose target does not exist at all
  is left alone, so that mkdocs reports it and the strict build fails.
"""

from __future__ import annotations

import os
import posixpath
import re
import sys
from pathlib import Path

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

#: the repository: the folder of mkdocs.yml (set by on_config)
ROOT = Path(__file__).resolve().parent.parent

#: pages made from repository files outside docs/, at the same path in the site
EXTRA_PAGES = ("CHANGELOG.md",)
#: the folder of the notebooks, shown as the tutorials (at the same path in the site)
TUTORIALS = "notebooks"
#: the stand-in scheme of a rewritten link between on_page_markdown and on_page_content
_REPO = "repo-file:"
CLI_MARKER = "<!-- cli-reference -->"
HARDWARE_MARKER = "<!-- hardware-catalog -->"
KEYWORDS_MARKER = "<!-- evolve-keywords -->"
#: the width the CLI's help is rendered at
HELP_COLUMNS = 100


def on_config(config):
    global ROOT
    ROOT = Path(config.config_file_path).resolve().parent
    # document this checkout's package, whatever else is installed
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    return config


@event_priority(100)  # before mkdocs-jupyter's on_files, which wraps the notebooks
def on_files(files, config):
    # as files of the repository root (src_dir), so that they keep their own path; mkdocs-jupyter
    # needs a File whose src_dir and src_uri lead to the notebook
    for path in [
        *sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / TUTORIALS).glob("*.ipynb")),
        *(p for p in EXTRA_PAGES if (ROOT / p).is_file()),
    ]:
        files.append(File(path, str(ROOT), config.site_dir, config.use_directory_urls))
    return files


def on_page_markdown(markdown, page, config, files):
    if CLI_MARKER in markdown:
        markdown = markdown.replace(CLI_MARKER, cli_reference())
    if HARDWARE_MARKER in markdown:
        markdown = markdown.replace(HARDWARE_MARKER, hardware_table())
    if KEYWORDS_MARKER in markdown:
        markdown = markdown.replace(KEYWORDS_MARKER, evolve_keywords())
    return rewrite_repo_links(markdown, page.file.src_uri, config, files)


def on_page_content(html, page, config, files):
    def url(m: re.Match) -> str:
        return f'{m.group(1)}="{repo_url(m.group(2), page, config)}"'

    return re.sub(rf'(href|src)="{_REPO}([^"]*)"', url, html)


# --- links to repository files --------------------------------------------------------------

_INLINE = re.compile(r"(\]\(\s*<?)([^)\s>]+)")
_REFERENCE = re.compile(r"^( {0,3}\[[^\]]+\]:\s*<?)([^\s>]+)", re.M)
_FENCE = re.compile(r"^ {0,3}(```|~~~)")


def repo_target(url: str, src_uri: str, config, files) -> str | None:
    """The repository path (posix, relative to the root) a page's link leads to, when it leads to
    an existing repository file or folder that is not in the site; else None (a page, an
    external link, an anchor, or a target that does not exist: mkdocs judges those)."""
    if re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:|^/|^#", url):
        return None
    path = url.split("#", 1)[0].split("?", 1)[0]
    if not path:
        return None
    target = posixpath.normpath(posixpath.join(posixpath.dirname(src_uri), path))
    docs = Path(config.docs_dir).resolve()
    absolute = (docs / target).resolve()
    if not absolute.is_relative_to(ROOT) or not absolute.exists():
        return None
    if not target.startswith("../"):
        file = files.get_file_from_path(target)
        if file is not None and not file.inclusion.is_excluded():
            return None  # a page or file of the site
        excluded = config.exclude_docs
        if absolute.is_dir() and not (excluded and excluded.match_file(target.rstrip("/") + "/")):
            return None  # a folder of the site
    rel = absolute.relative_to(ROOT).as_posix()
    return rel + ("/" if absolute.is_dir() else "") + url[len(url.split("#", 1)[0]) :]


def rewrite_repo_links(markdown: str, src_uri: str, config, files) -> str:
    """`markdown` with each link to a repository file outside the site replaced by a stand-in
    (`repo-file:PATH`) that `on_page_content` turns into its final address; fenced code is left
    as it is."""

    def one(m: re.Match) -> str:
        target = repo_target(m.group(2), src_uri, config, files)
        return m.group(0) if target is None else f"{m.group(1)}{_REPO}{target}"

    out, fence = [], None
    for line in markdown.splitlines(keepends=True):
        m = _FENCE.match(line)
        if fence is None and m:
            fence = m.group(1)
        elif fence is not None:
            if m and m.group(1) == fence:
                fence = None
        else:
            line = _REFERENCE.sub(one, _INLINE.sub(one, line))
        out.append(line)
    return "".join(out)


def repo_url(path: str, page, config) -> str:
    """The address of a repository file: on the repository's site where mkdocs.yml names one
    (`repo_url`), else relative from the built page to the file in this checkout (a site built
    into the checkout and opened from disk)."""
    if config.repo_url:
        kind = "tree" if path.split("#", 1)[0].endswith("/") else "blob"
        return f"{config.repo_url.rstrip('/')}/{kind}/main/{path}"
    here = Path(page.file.abs_dest_path).parent
    rel = os.path.relpath(ROOT / path.split("#", 1)[0], here).replace(os.sep, "/")
    anchor = path[len(path.split("#", 1)[0]) :]
    return rel + ("/" if path.split("#", 1)[0].endswith("/") else "") + anchor


# --- the CLI reference ----------------------------------------------------------------------


def cli_reference() -> str:
    """Markdown: the `--help` of `swarmcode-torch` and of each of its commands, as a user sees
    it at a width of HELP_COLUMNS."""
    import typer
    from typer.testing import CliRunner

    from swarmcode_torch.app.cli import app

    runner = CliRunner()
    env = {"COLUMNS": str(HELP_COLUMNS), "NO_COLOR": "1", "TERM": "dumb"}
    parts: list[str] = []

    def walk(command, path: list[str]) -> None:
        r = runner.invoke(
            app, [*path, "--help"], prog_name="swarmcode-torch", env=env, catch_exceptions=False
        )
        if r.exit_code != 0:
            raise RuntimeError(
                f"swarmcode-torch {' '.join(path)} --help exited {r.exit_code}: {r.output}"
            )
        title = " ".join(["swarmcode-torch", *path])
        parts.extend(
            [
                f"## `{title}`" if path else "## Commands",
                "",
                "```text",
                r.output.rstrip(),
                "```",
                "",
            ]
        )
        subs = {n: c for n, c in getattr(command, "commands", {}).items() if not c.hidden}
        if subs:  # --help cuts each command's summary to the terminal's width: here in full
            parts.extend(["| command | what it does |", "|---|---|"])
            for name, sub in subs.items():
                summary = " ".join((sub.help or "").split("\n\n", 1)[0].split())
                cell = summary.replace("|", "\\|")
                parts.append(f"| `{' '.join([*path, name])}` | {cell} |")
            parts.append("")
        for name, sub in subs.items():
            walk(sub, [*path, name])

    walk(typer.main.get_command(app), [])
    return "\n".join(parts)


def evolve_keywords() -> str:
    """Markdown: a table of the keywords of `swarmcode_torch.evolve` that are declared with the
    command line's options (`run_options.RUN_OPTIONS`, `api=True`): keyword, default, the option
    it matches and its help."""
    from swarmcode_torch.app.run_options import EVOLVE_OPTIONS

    def cell(text: str) -> str:
        return text.replace("|", "\\|")

    rows = ["| keyword | default | as the option | what it is |", "|---|---|---|---|"]
    for o in EVOLVE_OPTIONS:
        if o.api:
            default = o.keyword().default
            rows.append(
                f"| `{o.name}` | `{default!r}` | `{o.spelling}` | {cell(' '.join(o.help.split()))} |"
            )
    return "\n".join(rows)


# --- the hardware catalog -------------------------------------------------------------------


def hardware_table() -> str:
    """Markdown: one row per field of a hardware catalog, from the checks the catalog goes
    through (`sim.hardware`) and the built-in catalog's values and comments."""
    from swarmcode_torch.sim import hardware as hw

    text = hw.default_catalog_bytes().decode("utf-8")
    comments: dict[tuple[str, str], str] = {}
    section = ""
    for line in text.splitlines():
        if m := re.match(r"\s*\[([^\]]+)\]", line):
            section = m.group(1)
        elif m := re.match(r"\s*([A-Za-z_]+)\s*=[^#]*#\s*(.*)", line):
            comments[section, m.group(1)] = m.group(2).strip()
    cat = hw.default_catalog()
    rows = [
        "| section | key | type | allowed values | built-in value | meaning |",
        "|---|---|---|---|---|---|",
    ]
    for section, key, name, per_tier, (lo, hi, lo_ok) in hw._CATALOG_FIELDS:
        kind = f"list of {hw.NUM_TIERS} numbers (tiers 1, 2, 3)" if per_tier else "number"
        bound = f"{'[' if lo_ok else '('}{lo:g}, {hi:g}]"
        value = getattr(cat, name)
        shown = ", ".join(f"{x:g}" for x in value) if per_tier else f"{value:g}"
        rows.append(
            f"| `[{section}]` | `{key}` | {kind} | {bound} | "
            f"{'[' + shown + ']' if per_tier else shown} | "
            f"{comments.get((section, key), '').replace('|', '/')} |"
        )
    return "\n".join(rows)
