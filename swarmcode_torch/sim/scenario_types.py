"""What a scenario is: its dataclasses, its error and the bounds of its fields (`sim.scenario`
reads and checks them)."""

from __future__ import annotations

from dataclasses import dataclass, field

from .hardware import R_MAX, R_MIN, Catalog, default_catalog

EFFECTORS = {"suction": 0, "pincher": 1}
MAX_GRIPS = 3
#: Robot radii the hardware genes can take.
ROBOT_RADII = (R_MIN, R_MAX)
#: Upper bounds of a scenario's sizes: beyond them a world is certainly not what was meant.
MAX_ARENA = 10_000.0  # m
MAX_EPISODE_TICKS = 1_000_000
MAX_NUMBER = 1e15  # any number of a scenario: float32 holds it with room to spare
#: The most bytes read from a scenario file or the hardware catalog file it names.
MAX_FILE_BYTES = 16 * 2**20
#: The longest scenario name, description and --scenario name or path (characters).
MAX_NAME = 200
MAX_DESCRIPTION = 10_000
MAX_PATH = 4096
#: The most packages a scenario places (each environment places and senses every one).
MAX_PACKAGES = 10_000
#: Room kept free around a package for a robot at each grip (layout.make_layouts: size + 0.6).
PACKAGE_CLEARANCE = 0.6
#: The scalar fields of a scenario file, in the order a written one gives them (the tables
#: `obstacles`, `packages` and `hardware` follow).
SCALAR_FIELDS = (
    "name",
    "description",
    "arena",
    "base_radius",
    "num_robots",
    "episode_ticks",
    "species_overhead",
)
#: The keys a scenario file may have (the loader checks them against these): at its top level,
#: in [obstacles] and in each [[packages]].
FIELDS = (*SCALAR_FIELDS, "obstacles", "packages", "hardware")
OBSTACLE_FIELDS = ("count", "radius")
PACKAGE_FIELDS = (
    "kind",
    "count",
    "distance",
    "mass",
    "effector",
    "grips",
    "radius_band",
    "size",
    "distance_weighting",
)


class ScenarioError(ValueError):
    """A scenario that cannot be loaded; the message names the bad field."""


@dataclass(frozen=True)
class PackageClass:
    """A group of packages that share a spec; `count` of them are placed in every environment."""

    kind: str  # "individual" or "collab"
    count: int
    distance: tuple[float, float]  # from the base centre (m)
    mass: tuple[float, float]  # kg; heavier near the base when distance_weighting
    grips: tuple[int, ...]  # effector of each grip point (one for an individual package)
    radius_band: tuple[float, float] = (0.0, 10.0)  # robot radii that can lift it (m)
    distance_weighting: bool = False
    size: float = 0.2  # package radius (m); grip points lie just outside it

    @property
    def label(self) -> str:
        """e.g. 'pincher 16-24 kg, r 0.32-0.5 m' or 'collab suction+pincher 30-40 kg'."""
        names = {v: k for k, v in EFFECTORS.items()}
        eff = "+".join(names[e] for e in self.grips)
        collab = "collab " if self.kind == "collab" else ""
        text = f"{collab}{eff} {self.mass[0]:g}-{self.mass[1]:g} kg"
        if self.radius_band != (0.0, 10.0):
            text += f", r {self.radius_band[0]:g}-{self.radius_band[1]:g} m"
        return text


@dataclass(frozen=True)
class Scenario:
    """A foraging world: arena, base, obstacles, packages and swarm size."""

    name: str
    description: str
    arena: float  # side of the square arena (m); the base is at its centre
    base_radius: float
    num_robots: int
    episode_ticks: int
    species_overhead: float  # $ fabrication overhead per distinct species in a team
    obstacle_count: int
    obstacle_radius: tuple[float, float]
    packages: tuple[PackageClass, ...]
    #: the hardware catalog its robots are built from: the scenario's own (its `hardware` key)
    #: or the built-in one (data/hardware.toml)
    hardware: Catalog = field(default_factory=default_catalog)

    @property
    def num_packages(self) -> int:
        return sum(p.count for p in self.packages)

    @property
    def max_grips(self) -> int:
        return max((len(p.grips) for p in self.packages), default=1)
