"""The generator's constants and what it returns: a `World` and its `Niche`s."""

from __future__ import annotations

from dataclasses import dataclass

from ..scenario import EFFECTORS, Scenario

#: The families of worlds (`generate_world(family=...)`):
#: "classes": one exclusive package class per niche;
#: "generalist": plus one class that the designs of two niches of one effector can both lift (a
#: radius band over both of theirs, lighter than either's packages); the niche count is unchanged;
#: "collab": plus one collaborative class, one grip per effector of the niches (two grips of the
#: same effector where the niches have one), light enough per grip for the niches' designs: it
#: needs no design beyond the niches', so the niche count is unchanged;
#: "single": 2 or 3 classes of one effector with different radius bands and masses that one
#: design (a radius inside every band, strong enough for every class) lifts: niches = 1.
FAMILIES = ("classes", "generalist", "collab", "single")
#: "disjoint": the radius bands of one effector's niches do not meet; "overlapping": adjacent
#: bands overlap and the larger band's packages are too heavy for the robots in the overlap.
BAND_MODES = ("disjoint", "overlapping")
MAX_NICHES = 6
#: The most niches one effector holds: radius bands of about a third of [R_MIN, R_MAX] each.
NICHES_PER_EFFECTOR = 3
#: Draws of one seed before `generate_world` gives up on the knobs.
MAX_DRAWS = 64
#: kg kept between a class's mass and what the robots that must (or must not) lift it can lift.
LIFT_MARGIN = 2.0
#: Generator seeds of the two study splits: disjoint, fixed (`split_seeds`).
TRAIN_SEEDS = range(1000, 2000)
TEST_SEEDS = range(5000, 6000)
OBSTACLE_RADIUS = (0.4, 0.8)
INDIVIDUAL_SIZE = 0.2
COLLAB_SIZE = 0.5
MAX_SEED = 2**63 - 1
_NAMES = {v: k for k, v in EFFECTORS.items()}


class _Redraw(Exception):
    """A draw that does not give a solvable world with the niches asked for; why, in words."""


@dataclass(frozen=True)
class Niche:
    """One niche of a generated world: the designs with `effector` and a radius in `band` are
    the ones that lift package class `exclusive` (an index into the scenario's packages)."""

    effector: str
    band: tuple[float, float]
    exclusive: int

    @property
    def label(self) -> str:
        return f"{self.effector}, robots {self.band[0]:g}-{self.band[1]:g} m"


@dataclass(frozen=True)
class World:
    """A generated world: the scenario, the TOML table it is written as, the niches it needs
    and how it was drawn. `world_toml` writes it as a scenario file."""

    seed: int
    #: the knobs it was drawn with (JSON values), `generate_world`'s keywords
    knobs: dict
    #: the fewest distinct robot designs that together lift every package class
    niches: int
    niche_designs: tuple[Niche, ...]
    scenario: Scenario
    #: the scenario as the TOML table of an ordinary scenario file (`scenario_from_dict` of it
    #: gives `scenario`)
    table: dict
    #: a note on each package class (what it is for), written as a comment above it
    notes: tuple[str, ...]
    description: str
    #: the fabrication budget in $ it was drawn for (a run setting, not part of the scenario)
    budget: float | None
    #: $ of the cheapest robot of each niche that lifts the heaviest package of its class
    cheapest: tuple[float, ...]
    #: $: the least a team of num_robots robots with one robot of each niche can cost (the
    #: others at the price of the cheapest robot there is) plus the species overhead per niche
    min_team_cost: float
    #: ("train" | "test", index) for a study world (`study_world`)
    study: tuple[str, int] | None = None
