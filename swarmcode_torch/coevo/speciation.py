"""NEAT-style dynamic speciation: the SwarmCoDe genome distance and prototype-based species."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from ..sim.bt import NUM_OPCODES
from ..sim.tensors import arange, cast
from .config import DistanceWeights, SwarmCoDeConfig
from .population import R_MAX, R_MIN, Population

#: speciate precomputes the full [P, P] distance matrix when P * P is at most this.
_FULL_MATRIX_MAX = 1 << 24


@dataclass(frozen=True, eq=False)
class SpeciationResult:
    """species [P] long ids; proto_ids [K] long (carried-over first, then new in founding order);
    proto_index [K] long prototype rows; next_species_id: the next unused id; prototypes [K]:
    the prototypes' genomes (rows proto_index); distance [P, P] float32: D between the
    population's genomes where it was computed (else None)."""

    species: Tensor
    proto_ids: Tensor
    proto_index: Tensor
    next_species_id: int
    prototypes: Population
    distance: Tensor | None = None


def hamming(a: Tensor, b: Tensor) -> Tensor:
    """[Pa, L] bool, [Pb, L] bool -> [Pa, Pb] float32 Hamming distances (exact integer counts):
    the bits set in a and not in b plus those set in b and not in a, in one product."""
    af, bf = a.float(), b.float()
    return torch.cat([af, 1.0 - af], 1) @ torch.cat([1.0 - bf, bf], 1).T


@functools.lru_cache(maxsize=8)
def _opcode_rows(device: torch.device) -> Tensor:
    """[NUM_OPCODES, NUM_OPCODES] float32 identity: row o is opcode o one-hot (built once per
    device, never written to)."""
    return torch.eye(NUM_OPCODES, device=device)


class _Genes:
    """What D reads of a population, each part computed on its first use and kept: the
    distances of one population to itself and to others read it once."""

    def __init__(self, pop: Population):
        self.pop = pop

    @functools.cached_property
    def bits(self) -> Tensor:
        """[P, 2 L_tag] float32: the tag bits, then their complements (`hamming`'s left side)."""
        t = self.pop.tag.float()
        return torch.cat([t, 1.0 - t], 1)

    @functools.cached_property
    def flipped(self) -> Tensor:
        """[P, 2 L_tag] float32: the complements, then the bits (`hamming`'s right side)."""
        return self.bits.roll(self.pop.tag.shape[1], 1)

    @functools.cached_property
    def one_hot_bt(self) -> Tensor:
        """[P, L * NUM_OPCODES] float32: the opcodes one-hot."""
        return _opcode_rows(self.pop.bt.device)[cast(self.pop.bt, torch.long)].flatten(1)

    @functools.cached_property
    def hw(self) -> Tensor:
        return self.pop.hardware_vector()

    @functools.cached_property
    def radius(self) -> Tensor:
        return cast(self.pop.radius, torch.float)

    @functools.cached_property
    def effector_col(self) -> Tensor:
        """[P, 1] the effectors, as the rows' side of a pairwise comparison."""
        return self.pop.effector[:, None]

    @functools.cached_property
    def radius_col(self) -> Tensor:
        """[P, 1] the radii, as the rows' side of a pairwise difference."""
        return self.radius[:, None]


def _weighted(w: float, d: Tensor) -> Tensor:
    """w * d (d itself for a weight of 1: the product would be d exactly)."""
    return d if w == 1.0 else w * d


def _design_terms(a: _Genes, b: _Genes, w: DistanceWeights) -> tuple[Tensor, ...]:
    """The hardware terms of D (`distance_terms`'): hw, tool, size, each [Pa, Pb] float32."""
    d_hw = torch.cdist(a.hw, b.hw, compute_mode="donot_use_mm_for_euclid_dist")
    d_hw = d_hw / math.sqrt(a.hw.shape[1])
    d_tool = (a.effector_col != b.pop.effector).float()
    d_size = (a.radius_col - b.radius).abs() / (R_MAX - R_MIN)
    return _weighted(w.w_hw, d_hw), _weighted(w.w_tool, d_tool), _weighted(w.w_size, d_size)


def _terms(a: _Genes, b: _Genes, w: DistanceWeights) -> dict[str, Tensor]:
    """`distance_terms` of what D reads of two populations (b may be a)."""
    pa, pb = a.pop.size, b.pop.size
    dev = a.pop.bt.device
    l_tag = a.pop.tag.shape[1]
    if l_tag > 0:
        d_tag = (a.bits @ b.flipped.T / l_tag) ** w.gamma  # the Hamming distance / L_tag
    else:
        d_tag = torch.zeros(pa, pb, device=dev)
    l_bt = a.pop.bt.shape[1]
    if l_bt > 0:
        d_bt = 1.0 - (a.one_hot_bt @ b.one_hot_bt.T) / l_bt
    else:
        d_bt = torch.zeros(pa, pb, device=dev)
    hw, tool, size = _design_terms(a, b, w)
    return {
        "tag": _weighted(w.w_tag, d_tag),
        "hw": hw,
        "bt": _weighted(w.w_bt, d_bt),
        "tool": tool,
        "size": size,
    }


def distance_terms(
    a: Population, b: Population, w: DistanceWeights = DistanceWeights()
) -> dict[str, Tensor]:
    """Genomes [Pa], [Pb] -> the weighted terms of D, each [Pa, Pb] float32, in the order of the
    sum: tag = w_tag (H/L)^gamma, hw = w_hw d_hw, bt = w_bt d_bt, tool = w_tool d_tool,
    size = w_size d_size. (b may be a itself: what the two share is computed once.)

    H: tag Hamming distance, L: tag length; d_hw: Euclidean distance of `hardware_vector()`
    / sqrt(its dimension), the two continuous operating points;
    d_bt: fraction of BT slots whose opcode differs; d_tool: effectors differ;
    d_size: |dr| / (R_MAX - R_MIN).
    """
    ga = _Genes(a)
    return _terms(ga, ga if b is a else _Genes(b), w)


def _sum(t: dict[str, Tensor]) -> Tensor:
    """D, the sum of its terms in their order."""
    return t["tag"] + t["hw"] + t["bt"] + t["tool"] + t["size"]


def distance(a: Population, b: Population, w: DistanceWeights = DistanceWeights()) -> Tensor:
    """Genomes [Pa], [Pb] -> [Pa, Pb] float32 D = w_tag (H/L)^gamma + w_hw d_hw + w_bt d_bt
    + w_tool d_tool + w_size d_size (the sum of `distance_terms`)."""
    return _sum(distance_terms(a, b, w))


def design_distance(proto: Population, w: DistanceWeights = DistanceWeights()) -> Tensor:
    """Genomes [K] -> [K, K] float32: the hardware terms of D between them (w_hw d_hw + w_tool
    d_tool + w_size d_size), how far apart their robots are as designs. The tag (a signal for
    partner choice, not a property of the robot) and the tree are left out: which partner's
    robots are most like a species' robots (`partner_admission = "substitute"`)."""
    g = _Genes(proto)
    hw, tool, size = _design_terms(g, g, w)
    return hw + tool + size


def speciate(
    genome: Population,
    species_hint: Tensor,
    prev_proto: Population | None,
    prev_proto_ids: Tensor,
    next_species_id: int,
    delta: float = SwarmCoDeConfig.delta,
    w: DistanceWeights = DistanceWeights(),
) -> SpeciationResult:
    """Population [P], hint [P] long (-1 none), previous prototypes [Kp] + ids [Kp] ->
    SpeciationResult.

    (1) Each previous species with >= 1 member by `species_hint` keeps its id; its new prototype is
    the member closest to the old prototype (ties: lowest row); memberless species go extinct.
    (2) Every other individual, in row order, joins the closest current prototype if D <= delta,
    else founds a new species (id next_species_id, next_species_id + 1, ...). Ties between
    prototypes go to the earliest prototype in `proto_ids` order.

    When P * P <= 2**24, the [P, P] distance matrix is computed once and the founders are found
    on the host from which pairs are within delta (one transfer, the only one: the number of
    species, which sizes what follows, is then known there); everything else is batched on the
    device. Else in rounds, one per new species + 1, each a [P, 1] distance column and a read on
    the host.
    """
    p = genome.size
    dev = genome.bt.device
    long_empty = torch.zeros(0, dtype=torch.long, device=dev)
    if p == 0:
        empty = genome.index(long_empty)
        return SpeciationResult(long_empty, long_empty, long_empty, next_species_id, empty)
    genes = _Genes(genome)  # what D reads of the population, for both of its distances here
    # (1) carry-over of surviving species: alive [Kp], closest [Kp] (the new prototype's row)
    prev_ids, alive, closest = _carry_over(genes, species_hint, prev_proto, prev_proto_ids, dev, w)
    if p * p > _FULL_MATRIX_MAX:
        return _speciate_in_rounds(genome, prev_ids, alive, closest, next_species_id, delta, w)
    full = _sum(_terms(genes, genes, w))
    row = arange(p, dev)[:, None]  # [P, 1] each row's number
    if closest is not None:
        assert alive is not None and prev_ids is not None
        d_cur = full[:, closest].masked_fill(~alive, math.inf)  # [P, Kp]
        carried = ((closest == row) & alive).any(1)
        min_d = d_cur.min(1).values
    else:
        d_cur, carried, min_d = None, torch.zeros(p, dtype=torch.bool, device=dev), None
    # (2) a candidate founds a species unless a founder before it is within delta
    cand = ~carried if min_d is None else ~carried & (min_d > delta)
    alive_at, founders = _founders(cand, alive, full <= delta)
    k, n_new = len(alive_at), len(founders)
    picks = _to_device(np.concatenate([alive_at, founders]).astype(np.int64), dev)
    new_rows = picks[k:]
    # every other row joins the closest of the carried prototypes and the founders before it
    d_new = full[:, new_rows].masked_fill(new_rows >= row, math.inf)
    if d_cur is not None:
        assert prev_ids is not None and closest is not None
        at = picks[:k]
        carried_ids, carried_rows = prev_ids[at], closest[at]
        d_new = torch.cat([d_cur[:, at], d_new], 1)
    else:
        carried_ids = carried_rows = long_empty
    proto_index = torch.cat([carried_rows, new_rows])
    own = torch.full((p,), -1, dtype=torch.long, device=dev)
    own[proto_index] = arange(k + n_new, dev)
    assign_pos = torch.where(own >= 0, own, d_new.argmin(1))
    return _result(genome, carried_ids, proto_index, assign_pos, next_species_id, n_new, full)


def _carry_over(
    genes: _Genes,
    species_hint: Tensor,
    prev_proto: Population | None,
    prev_proto_ids: Tensor,
    dev: torch.device,
    w: DistanceWeights,
) -> tuple[Tensor | None, Tensor | None, Tensor | None]:
    """`speciate`'s step (1): the previous species' ids [Kp], which have a member by the hint
    (alive [Kp] bool) and each one's member closest to its old prototype (closest [Kp], the
    lowest row of a tie); three Nones where there were no previous species."""
    if prev_proto is None or prev_proto_ids.numel() == 0:
        return None, None, None
    prev_ids = cast(prev_proto_ids, torch.long, dev)
    d_prev = _sum(_terms(genes, _Genes(prev_proto.to(dev)), w))  # [P, Kp]
    member = cast(species_hint, device=dev)[:, None] == prev_ids  # [P, Kp]
    alive = member.any(0)
    closest = d_prev.masked_fill(~member, math.inf).argmin(0)  # first min = lowest row
    return prev_ids, alive, closest


def _result(
    genome: Population,
    carried_ids: Tensor,
    proto_index: Tensor,
    assign_pos: Tensor,
    next_species_id: int,
    n_new: int,
    full: Tensor | None = None,
) -> SpeciationResult:
    """The species of both ways of `speciate`: the carried species' ids, then `n_new` new ones
    from `next_species_id`; each row's species at its prototype position `assign_pos` [P];
    `full`: the [P, P] distance matrix, where it was computed."""
    new_ids = torch.arange(
        next_species_id, next_species_id + n_new, dtype=torch.long, device=carried_ids.device
    )
    proto_ids = torch.cat([carried_ids, new_ids])
    return SpeciationResult(
        species=proto_ids[assign_pos],
        proto_ids=proto_ids,
        proto_index=proto_index,
        next_species_id=next_species_id + n_new,
        prototypes=genome.index(proto_index),
        distance=full,
    )


def _founders(cand: Tensor, alive: Tensor | None, near: Tensor) -> tuple[np.ndarray, list[int]]:
    """cand [P] bool, alive [Kp] bool (None: no previous species), near [P, P] bool (D <= delta)
    -> the positions of the alive species and the founders' rows, read on the host in one
    transfer: a candidate founds a species unless a founder before it is near it (a greedy pass
    in row order, sequential by definition)."""
    p = cand.numel()
    flags = [cand] + ([alive] if alive is not None else []) + [near.T.reshape(-1)]
    host = cast(torch.cat(flags), device="cpu").numpy()
    kp = 0 if alive is None else alive.numel()
    near_h = host[p + kp :].reshape(p, p)  # near_h[f]: the rows near row f
    founders: list[int] = []
    blocked = np.zeros(p, dtype=bool)
    for r in np.flatnonzero(host[:p]):
        if not blocked[r]:
            founders.append(int(r))
            blocked |= near_h[r]
    return np.flatnonzero(host[p : p + kp]), founders


def _to_device(a: np.ndarray, device: torch.device) -> Tensor:
    """A host array on `device`, without waiting for the device: from pinned memory on CUDA."""
    t = torch.from_numpy(a)
    if device.type != "cuda":
        return cast(t, device=device)
    return t.pin_memory().to(device, non_blocking=True)


def _speciate_in_rounds(
    genome: Population,
    prev_ids: Tensor | None,
    alive: Tensor | None,
    closest: Tensor | None,
    next_species_id: int,
    delta: float,
    w: DistanceWeights,
) -> SpeciationResult:
    """`speciate` of a population too large for its [P, P] distance matrix: the founders in
    rounds, one [P, 1] distance column and one read on the host per round."""
    p = genome.size
    dev = genome.bt.device
    idx = torch.arange(p, device=dev)
    if closest is not None:
        assert alive is not None and prev_ids is not None
        carried_rows, carried_ids = closest[alive], prev_ids[alive]
    else:
        carried_rows = carried_ids = torch.zeros(0, dtype=torch.long, device=dev)
    k = int(carried_rows.numel())

    assigned = torch.zeros(p, dtype=torch.bool, device=dev)
    assign_pos = torch.full((p,), -1, dtype=torch.long, device=dev)  # position in the proto list
    assigned[carried_rows] = True
    assign_pos[carried_rows] = torch.arange(k, device=dev)
    if k > 0:
        d_cur = distance(genome, genome.index(carried_rows), w)  # [P, Kc]
        arg = d_cur.argmin(1)
        min_d = d_cur.gather(1, arg[:, None]).squeeze(1)
    else:
        arg = torch.zeros(p, dtype=torch.long, device=dev)
        min_d = torch.full((p,), math.inf, device=dev)
    new_rows: list[int] = []
    while True:
        cand = ~assigned & (min_d > delta)
        # the first founder candidate, -1 if none: one read on the host per round
        f = int(torch.where(cand.any(), cand.to(torch.int32).argmax(), -1))
        if f < 0:
            break
        block = ~assigned & (idx < f)
        assign_pos = torch.where(block, arg, assign_pos)
        assigned = assigned | block
        assigned[f] = True
        assign_pos[f] = k
        new_rows.append(f)
        d_new = distance(genome, genome.index(slice(f, f + 1)), w)[:, 0]
        better = d_new < min_d  # strict: ties keep older
        arg = torch.where(better, torch.full_like(arg, k), arg)
        min_d = torch.where(better, d_new, min_d)
        k += 1
    assign_pos = torch.where(assigned, assign_pos, arg)

    proto_index = torch.cat([carried_rows, torch.tensor(new_rows, dtype=torch.long, device=dev)])
    return _result(genome, carried_ids, proto_index, assign_pos, next_species_id, len(new_rows))
