"""Whether a niche's class can be brought home within an episode (`fetch_deliveries`,
`out_of_reach`): a class that the lift rule gives to a niche but that no swarm of its designs
carries to the base in time is a niche the fitness does not ask for (docs/WORLDS.md, "Reach").

The test: the class alone in its world (the same arena, obstacles, swarm size and episode), a full
swarm of one hand design (the niche's effector, every tier the best, the torque and battery
operating points at 1) running `FETCH`, at three radii of the niche's band, on `REACH_LAYOUTS`
layouts; the class is out of reach when the best radius delivers fewer than `REACH_SHARE` of
its packages an episode. The rule and its constants were fixed on the niche study's train worlds
(experiments/2026-12-05-niche-generalization-v08/README.md, "The world audit").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import torch

from ..bt import (
    ACT_DROP,
    ACT_MOVE_TO_BASE,
    ACT_MOVE_TO_PACK,
    ACT_PICK_UP,
    COND_HAS_PACKAGE,
    COND_NEAR_BASE,
    COND_NEAR_PACKAGE,
    END,
    SEL,
    SEQ,
    build_tables,
    encode,
)
from ..fused import FusedTicks
from ..hardware import NUM_TIERS, phenotype
from ..layout import make_layouts
from ..rollout import rollout
from ..scenario import EFFECTORS, Scenario
from ..state import Robots, WorldParams
from .model import Niche

#: A niche's class is out of reach when the best hand swarm delivers fewer than this share of
#: its packages an episode.
REACH_SHARE = 0.5
#: Layouts (seeds 0 .. REACH_LAYOUTS - 1 of one generator) each radius is tried on.
REACH_LAYOUTS = 16
#: Fetch and return: holding a package, drop it at the base or go there; else pick up the
#: package at hand or go to the nearest one.
FETCH = (
    SEL, SEQ, COND_HAS_PACKAGE, SEL, SEQ, COND_NEAR_BASE, ACT_DROP, END, ACT_MOVE_TO_BASE, END,
    END, SEQ, COND_NEAR_PACKAGE, ACT_PICK_UP, END, ACT_MOVE_TO_PACK, END,
)  # fmt: skip


#: the tick of every reach test of a process (one build or load of the extension, one warning)
_TICK = FusedTicks()


def fetch_deliveries(
    s: Scenario,
    cls: int,
    effector: str,
    radii: Sequence[float],
    layouts: int = REACH_LAYOUTS,
    seed: int = 0,
) -> list[float]:
    """Packages of class `cls` of `s` delivered an episode (the mean over `layouts` layouts of
    the class alone), by a swarm of `s.num_robots` robots of the hand design of each radius.

    Args:
        s: the scenario.
        cls: the package class (an index into `s.packages`).
        effector: "pincher" or "suction".
        radii: the robot radii (m) to try, one swarm each.
        layouts: layouts each swarm runs on, drawn from `torch.Generator().manual_seed(seed)`.
        seed: the layouts' seed.

    Returns:
        One mean a radius, in the order of `radii`. One rollout of every radius and layout
        together, with the fused C++ tick (`FusedTicks`, which gives the Python tick's results to
        the bit, and falls back to it, with one warning a process, where it cannot be built);
        the same arguments give the same figures.
    """
    alone = replace(s, packages=(s.packages[cls],))
    lay = make_layouts(alone, layouts, torch.Generator().manual_seed(seed))
    k, n = len(radii), s.num_robots
    lay = lay.select(torch.arange(layouts).repeat(k))
    radius = torch.tensor(radii, dtype=torch.float32).repeat_interleave(layouts)[:, None]
    radius = radius.expand(k * layouts, n)
    best = torch.full_like(radius, NUM_TIERS - 1, dtype=torch.long)
    ones = torch.ones_like(radius)
    kind = torch.full_like(best, EFFECTORS[effector])
    ph = phenotype(radius, best, best, best, ones, ones, kind, s.hardware)
    robots = Robots.from_phenotype(
        ph, torch.ones_like(best, dtype=torch.bool), torch.zeros_like(best)
    )
    tables = build_tables(encode(FETCH, len(FETCH))[None])
    m = rollout(lay, robots, tables, WorldParams.for_scenario(s), s.episode_ticks, step_fn=_TICK)
    done = (m["delivered_individual"] + m["delivered_collab"]).view(k, layouts).mean(1)
    return [float(x) for x in done]


def niche_reach(s: Scenario, niche: Niche) -> float:
    """The share of `niche`'s exclusive class's packages the best of three hand swarms (radii
    0.01 m inside each end of its band and its middle) delivers an episode (`fetch_deliveries`)."""
    lo, hi = niche.band
    radii = (lo + 0.01, (lo + hi) / 2, hi - 0.01) if hi - lo > 0.02 else ((lo + hi) / 2,)
    best = max(fetch_deliveries(s, niche.exclusive, niche.effector, radii))
    return best / s.packages[niche.exclusive].count


def out_of_reach(
    s: Scenario, niches: Sequence[Niche], least: float = REACH_SHARE
) -> list[tuple[int, float]]:
    """(niche index, reach) of each niche whose exclusive class is out of reach: its best hand
    swarm delivers fewer than `least` of the class's packages an episode (`niche_reach`)."""
    out = []
    for i, niche in enumerate(niches):
        r = niche_reach(s, niche)
        if r < least:
            out.append((i, r))
    return out
