"""The standard study worlds: fixed, disjoint train and test splits (docs/WORLDS.md)."""

from __future__ import annotations

from dataclasses import replace

from ..scenario import ScenarioError
from .draw import generate_world
from .model import TEST_SEEDS, TRAIN_SEEDS, World

#: The standard study worlds: the knobs of world K of either split (its seed is the split's
#: K-th, `split_seeds`). Three of each niche count 1-5, across the families, inversions and
#: overlapping bands; the same knobs in both splits, so that train and test differ by seed only.
STUDY_SPECS: tuple[dict, ...] = (
    dict(niches=1, family="classes", effectors=("pincher",)),
    dict(niches=1, family="single", effectors=("suction",)),
    dict(niches=1, family="collab", effectors=("pincher",), inversion=True),
    dict(niches=2, family="classes"),
    dict(niches=2, family="classes", effectors=("suction",), inversion=True),
    dict(niches=2, family="generalist", effectors=("pincher",)),
    dict(niches=3, family="classes"),
    dict(niches=3, family="classes", bands="overlapping", mass=(2.0, 120.0)),
    dict(niches=3, family="collab", inversion=True),
    dict(niches=4, family="classes"),
    dict(niches=4, family="generalist", inversion=True),
    dict(niches=4, family="classes", bands="overlapping", mass=(2.0, 120.0)),
    dict(niches=5, family="classes"),
    dict(niches=5, family="collab", inversion=True),
    dict(niches=5, family="generalist", bands="overlapping", mass=(2.0, 120.0)),
)
SPLITS = ("train", "test")


def split_seeds(split: str) -> range:
    """The generator seeds of a study split (the two are disjoint).

    Args:
        split: "train" (seeds 1000-1999) or "test" (5000-5999).

    Returns:
        The split's seeds.
    """
    if split == "train":
        return TRAIN_SEEDS
    if split == "test":
        return TEST_SEEDS
    raise ScenarioError(f"split: expected 'train' or 'test', got {split!r:.60}")


def study_world(split: str, index: int) -> World:
    """Standard study world `index` of a split, named study-SPLIT-INDEX.

    Args:
        split: "train" or "test".
        index: 0 .. len(STUDY_SPECS) - 1.

    Returns:
        `generate_world` of the split's index-th seed with the knobs `STUDY_SPECS[index]`.
    """
    seeds = split_seeds(split)
    if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(STUDY_SPECS):
        raise ScenarioError(
            f"index: expected an integer in [0, {len(STUDY_SPECS) - 1}], got {index!r:.60}"
        )
    spec = STUDY_SPECS[index]
    # drawn as the splits were, before the reach check existed (min_reach 0): their worlds and
    # every result on them stay valid (docs/WORLDS.md, "Reach")
    world = generate_world(seeds[index], name=f"study-{split}-{index:02d}", min_reach=0.0, **spec)
    return replace(world, study=(split, index))


def study_worlds(split: str) -> list[World]:
    """The standard study worlds of a split: 15 worlds, three of each niche count 1-5.

    Args:
        split: "train" or "test".

    Returns:
        `study_world` of each index.
    """
    return [study_world(split, i) for i in range(len(STUDY_SPECS))]
