"""Run the tutorials top to bottom and save them with their outputs, as the docs site shows them.

    python notebooks/execute.py            # every notebook here
    python notebooks/execute.py 01_quickstart.ipynb

Each notebook runs in a fresh kernel from this folder (about 10 s each on 2 cores); the sweep
tutorial reads the committed budget study. Run it after a change that alters what a tutorial
prints or draws; `tests/e2e/test_notebooks.py` checks the saved outputs are complete.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def execute(path: Path) -> None:
    import nbclient
    import nbformat

    nb = nbformat.read(path, as_version=4)
    nbclient.NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(HERE)}}
    ).execute()
    nbformat.write(nb, path)


def main(argv: list[str]) -> int:
    paths = [HERE / a for a in argv] or sorted(HERE.glob("*.ipynb"))
    for path in paths:
        if path.suffix != ".ipynb" or not path.is_file():
            print(f"error: no notebook {path}", file=sys.stderr)
            return 2
        print(f"running {path.name} ...", flush=True)
        execute(path)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
