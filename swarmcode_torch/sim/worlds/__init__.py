"""Generated worlds: scenarios drawn from a seed and a few knobs, each with the number of niches
it needs known by construction (docs/WORLDS.md).

A *niche* is a robot design a world needs: an (effector, radius band) whose designs alone can
lift one of the world's package classes, its *exclusive* class. The generator draws one
exclusive class per niche so that no design lifts the exclusive classes of two niches (they
differ in effector, in radius band, or, where two bands of one effector overlap, in mass: the
robots in the overlap are too weak for the larger band's packages), and so that the niche's
strongest designs lift its class's heaviest package. Then

    niches = the fewest distinct robot designs that together can lift every package class
             (a collaborative class: every one of its grips),

by the simulator's own lift rule (`sim.state.capabilities`: the effector, the radius band, a
payload and a drive force for the load). `generate_world` checks the count on every world it
returns: it searches the designs the hardware catalog can build (`fewest_designs`), and a world
whose count is not the one asked for, that some class makes unsolvable, or (`min_reach`) whose
niche's class no swarm of its designs brings home within an episode, is drawn again.

Everything is drawn from `random.Random(seed)`: the same seed and knobs give the same world
and byte for byte the same TOML (`world_toml`), which `parse_scenario` / `load_scenario` read
back into the same `Scenario`. `split_seeds` and `study_worlds` give fixed, disjoint train and
test sets of worlds.

The generator is split by job: `model` (its constants, `World`, `Niche`), `lift` (the lift rule
searched: `max_lift`, `fewest_designs`, `cheapest_robot`, `lift_shares`, `needles`), `reach`
(whether a niche's class can be brought home in an episode: `fetch_deliveries`, `niche_reach`,
`out_of_reach`), `knobs` (the knobs checked), `draw` (`generate_world`), `writing`
(`world_toml`, `world_command`) and `study` (the study splits); every public name is importable
from here.
"""

from .draw import generate_world
from .lift import (
    NEEDLE_SHARE,
    SHARE_DESIGNS,
    cheapest_robot,
    fewest_designs,
    lift_shares,
    max_lift,
    needles,
)
from .model import (
    BAND_MODES,
    COLLAB_SIZE,
    FAMILIES,
    INDIVIDUAL_SIZE,
    LIFT_MARGIN,
    MAX_DRAWS,
    MAX_NICHES,
    MAX_SEED,
    NICHES_PER_EFFECTOR,
    OBSTACLE_RADIUS,
    TEST_SEEDS,
    TRAIN_SEEDS,
    Niche,
    World,
)
from .reach import FETCH, REACH_LAYOUTS, REACH_SHARE, fetch_deliveries, niche_reach, out_of_reach
from .study import SPLITS, STUDY_SPECS, split_seeds, study_world, study_worlds
from .writing import world_command, world_toml

__all__ = [
    "BAND_MODES",
    "COLLAB_SIZE",
    "FAMILIES",
    "INDIVIDUAL_SIZE",
    "LIFT_MARGIN",
    "MAX_DRAWS",
    "MAX_NICHES",
    "MAX_SEED",
    "FETCH",
    "NEEDLE_SHARE",
    "NICHES_PER_EFFECTOR",
    "OBSTACLE_RADIUS",
    "REACH_LAYOUTS",
    "REACH_SHARE",
    "SHARE_DESIGNS",
    "SPLITS",
    "STUDY_SPECS",
    "TEST_SEEDS",
    "TRAIN_SEEDS",
    "Niche",
    "World",
    "cheapest_robot",
    "fetch_deliveries",
    "fewest_designs",
    "generate_world",
    "lift_shares",
    "max_lift",
    "needles",
    "niche_reach",
    "out_of_reach",
    "split_seeds",
    "study_world",
    "study_worlds",
    "world_command",
    "world_toml",
]
