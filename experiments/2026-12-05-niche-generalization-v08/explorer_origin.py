"""Where the species of a run's last best team come from: the generation each was founded, and
whether that is the generation after an explorer's injection (`refound_source = "random"`
with `refound_after = 10`: copies put in at generation g, g a multiple of 10, found their
species at g + 1).

    python experiments/2026-12-05-niche-generalization-v08/explorer_origin.py RUN [RUN ...]

Prints one line a run (its last best team's species with their founding generations) and, over
all runs, the share of those species founded at 10k + 1 (k >= 1); without explorers about one
in ten founding generations falls there by chance.
"""

from __future__ import annotations

import sys
from pathlib import Path

from swarmcode_torch.app.checkpoints import load_checkpoint
from swarmcode_torch.app.summary import read_teams


def origins(run: Path) -> list[tuple[int, int]]:
    """(species, generation founded) of each species of the run's last best team."""
    first: dict[int, int] = {}
    for h in load_checkpoint(run)["history"]:
        for s in h["population"]:
            first.setdefault(int(s), h["generation"])
    teams = read_teams(run)
    last = teams[max(teams)]
    return [(s, first[s]) for s in sorted({int(d["species"]) for d in last["designs"]})]


def main() -> None:
    n = hits = 0
    for arg in sys.argv[1:]:
        run = Path(arg)
        o = origins(run)
        marks = [f"{s}@{g}{'*' if g > 1 and g % 10 == 1 else ''}" for s, g in o]
        print(run.name, " ".join(marks))
        late = [g for _, g in o if g > 1]
        n += len(late)
        hits += sum(g % 10 == 1 for g in late)
    print(f"founded after generation 1: {n}; at 10k + 1 (*): {hits} ({hits / max(n, 1):.0%})")


if __name__ == "__main__":
    main()
