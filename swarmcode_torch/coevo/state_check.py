"""Is a checkpoint's state dict one of the run's? `check_state_dict` names the first entry whose
shape, dtype or values do not fit the run's config (`run_state.load_state_dict` calls it before it
builds a state from the entries)."""

from __future__ import annotations

from dataclasses import fields

import torch
from torch import Tensor

from ..sim import bt
from .config import SwarmCoDeConfig
from .population import GENE_BOUNDS, GENE_VALUES, Population


def check_population(d, cfg: SwarmCoDeConfig, what: str, rows: int | None) -> int:
    """ValueError unless `d` is a genome state dict of `rows` rows (any number when None) of
    `cfg`'s tag and tree lengths, each field of its dtype and within its range; its rows."""
    if not isinstance(d, dict):
        raise ValueError(f"{what}: expected a table of tensors")
    names = [f.name for f in fields(Population)]
    missing = [n for n in names if not isinstance(d.get(n), Tensor)]
    if missing:
        raise ValueError(f"{what}: missing or not a tensor: {', '.join(missing)}")
    n = int(d["selectivity"].shape[0]) if d["selectivity"].dim() == 1 else -1
    if n < 0 or (rows is not None and n != rows):
        raise ValueError(
            f"{what}: {tuple(d['selectivity'].shape)} rows, expected "
            f"{rows if rows is not None else 'one dimension'}"
        )
    shapes = {"tag": (n, cfg.tag_length), "bt": (n, cfg.bt_length)}
    for name in names:
        t = d[name]
        want = shapes.get(name, (n,))
        if tuple(t.shape) != want:
            raise ValueError(
                f"{what}: {name} has shape {tuple(t.shape)}, expected {want} "
                "(population, tag_length and bt_length of the run's config)"
            )
        if name == "tag":
            if t.dtype != torch.bool:
                raise ValueError(f"{what}: tag has dtype {t.dtype}, expected torch.bool")
        elif name == "bt" or name in GENE_VALUES:
            hi = bt.NUM_OPCODES if name == "bt" else GENE_VALUES[name]
            if t.dtype != torch.long:
                raise ValueError(f"{what}: {name} has dtype {t.dtype}, expected torch.int64")
            if t.numel() and (int(t.min()) < 0 or int(t.max()) >= hi):
                raise ValueError(
                    f"{what}: {name} holds values outside 0..{hi - 1} "
                    f"({int(t.min())}..{int(t.max())})"
                )
        else:
            low, high = GENE_BOUNDS[name]
            if not t.dtype.is_floating_point:
                raise ValueError(f"{what}: {name} has dtype {t.dtype}, expected a float")
            if t.numel() and not (
                bool(torch.isfinite(t).all())
                and float(t.min()) >= low - 1e-6
                and float(t.max()) <= high + 1e-6
            ):
                raise ValueError(f"{what}: {name} holds values outside [{low}, {high}] (or NaN)")
    return n


def check_state_dict(d: dict, cfg: SwarmCoDeConfig) -> None:
    """ValueError naming the entry of a checkpoint whose tensors do not fit `cfg` (shapes,
    dtypes, value ranges: a population of cfg.population rows with cfg's tag and tree lengths,
    genes in their bounds, opcodes known, fitness finite, a generation in [0, generations])."""
    P = cfg.population
    gen = d.get("generation")
    if not isinstance(gen, int) or isinstance(gen, bool) or gen < 0:
        raise ValueError(f"generation must be an integer >= 0, got {gen!r:.40}")
    nid = d.get("next_species_id")
    if not isinstance(nid, int) or isinstance(nid, bool) or nid < 0:
        raise ValueError(f"next_species_id must be an integer >= 0, got {nid!r:.40}")
    check_population(d.get("genome"), cfg, "genome", P)
    for name, dtype, want in (
        ("species_hint", torch.long, (P,)),
        ("fitness", None, (P,)),
        ("has_fitness", torch.bool, (P,)),
        ("rng_state", torch.uint8, None),
    ):
        t = d.get(name)
        if not isinstance(t, Tensor):
            raise ValueError(f"{name}: expected a tensor")
        if want is not None and tuple(t.shape) != want:
            raise ValueError(
                f"{name} has shape {tuple(t.shape)}, expected {want} (the run's population)"
            )
        if dtype is not None and t.dtype != dtype:
            raise ValueError(f"{name} has dtype {t.dtype}, expected {dtype}")
    if d["rng_state"].dim() != 1:
        raise ValueError(
            f"rng_state has shape {tuple(d['rng_state'].shape)}, expected a generator state"
        )
    f = d["fitness"]
    if not f.dtype.is_floating_point or not bool(torch.isfinite(f).all()):
        raise ValueError("fitness holds NaN or infinite values (or is not a float tensor)")
    if P and (int(d["species_hint"].min()) < -1 or int(d["species_hint"].max()) >= max(nid, 1)):
        raise ValueError(f"species_hint holds ids outside -1..{nid - 1} (next_species_id {nid})")
    ids = d.get("proto_ids")
    if not isinstance(ids, Tensor) or ids.dim() != 1 or ids.dtype != torch.long:
        raise ValueError("proto_ids: expected a one-dimensional int64 tensor")
    if ids.numel() and (int(ids.min()) < 0 or int(ids.max()) >= max(nid, 1)):
        raise ValueError(f"proto_ids hold ids outside 0..{nid - 1} (next_species_id {nid})")
    if d.get("proto") is None:
        if ids.numel():
            raise ValueError("proto_ids without prototypes (proto is None)")
    else:
        check_population(d["proto"], cfg, "proto", int(ids.numel()))
    history = d.get("history")
    if (
        not isinstance(history, list)
        or len(history) != gen
        or not all(isinstance(h, dict) and h.get("generation") == i for i, h in enumerate(history))
    ):
        raise ValueError(f"history must hold one record per generation 0..{gen - 1}")
