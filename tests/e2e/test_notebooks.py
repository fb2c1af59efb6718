"""The notebooks run top to bottom on the CPU and show their figures (slow: `pytest -m slow`).

A code cell tagged `png` (cell metadata "tags") must show a PNG image, one tagged `gif` a GIF:
the figures of the notebooks are in their executed outputs, not lost to a backend switch."""

from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).parents[2] / "notebooks").glob("*.ipynb"))

#: tag -> (mime type its cell must output); and per notebook, how many cells carry each tag
IMAGE_TAGS = {"png": "image/png", "gif": "image/gif"}
EXPECTED_IMAGES = {
    "01_quickstart": {"png": 2, "gif": 1},  # metrics plots, species composition; the replay
    "02_analyze_run": {"png": 3},  # fitness curves, species composition, morphology
    "03_budget_sweep": {"png": 1},  # side by side with the paper
}


def image_cells(nb) -> dict[str, list]:
    cells: dict[str, list] = {}
    for c in nb.cells:
        for tag in c.get("metadata", {}).get("tags", []):
            if tag in IMAGE_TAGS:
                cells.setdefault(tag, []).append(c)
    return cells


def test_every_notebook_declares_its_figures():
    nbformat = pytest.importorskip("nbformat")
    assert {p.stem for p in NOTEBOOKS} == set(EXPECTED_IMAGES)
    for path in NOTEBOOKS:
        cells = image_cells(nbformat.read(path, as_version=4))
        assert {t: len(c) for t, c in cells.items()} == EXPECTED_IMAGES[path.stem], path.name


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_saved_notebooks_carry_their_outputs(path):
    """The docs site shows the tutorials with the outputs saved in them (`notebooks/execute.py`
    writes them): every code cell ran, in order, without an error, and each tagged figure is
    there."""
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.read(path, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert [c.get("execution_count") for c in code] == list(range(1, len(code) + 1)), (
        f"{path.name} is not saved executed top to bottom: run python notebooks/execute.py"
    )
    assert not [o for c in code for o in c.get("outputs", []) if o["output_type"] == "error"]
    for tag, cells in image_cells(nb).items():
        for c in cells:
            assert any(IMAGE_TAGS[tag] in o.get("data", {}) for o in c.get("outputs", [])), (
                f"{path.name}: no saved {IMAGE_TAGS[tag]} output in\n{c.source}"
            )


@pytest.mark.subprocess
@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, tmp_path, monkeypatch):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    # the kernel's temporary folder (TMPDIR, which its `tempfile` reads): empty at the end
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))
    # the sweep notebook makes its own small sweep (in a temporary folder) when given none
    monkeypatch.setenv("SWARMCODE_SWEEP", str(tmp_path / "no-sweep"))
    monkeypatch.delenv("SWARMCODE_RUN", raising=False)
    nb = nbformat.read(path, as_version=4)
    nbclient.NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}
    ).execute()
    errors = [
        o
        for c in nb.cells
        if c.cell_type == "code"
        for o in c.get("outputs", [])
        if o.get("output_type") == "error"
    ]
    assert not errors
    for tag, cells in image_cells(nb).items():
        mime = IMAGE_TAGS[tag]
        for c in cells:
            shown = [o for o in c.get("outputs", []) if mime in o.get("data", {})]
            assert shown, f"{path.name}: no {mime} output in the cell\n{c.source}"
    made = [c for c in nb.cells if c.cell_type == "code" and "TemporaryDirectory(" in c.source]
    assert made, f"{path.name} makes no temporary folder"
    left = sorted(p.name for p in tmp.iterdir() if p.name.startswith("swarmcode-"))
    assert not left, f"{path.name} left {left} behind"
    for c in nb.cells:  # a run made in a notebook shows its progress
        if c.cell_type == "code" and "sc.evolve(" in c.source:
            text = "".join(
                o.get("text", "") for o in c.get("outputs", []) if o.get("output_type") == "stream"
            )
            assert "done " in text and " left " in text, f"{path.name}: no progress\n{text}"
