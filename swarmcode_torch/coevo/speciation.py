"""NEAT-style dynamic speciation: the SwarmCoDe genome distance and prototype-based species."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from ..sim.bt import NUM_OPCODES
from .config import DistanceWeights, SwarmCoDeConfig
from .population import R_MAX, R_MIN, Population

#: speciate precomputes the full [P, P] distance matrix when P * P is at most this.
_FULL_MATRIX_MAX = 1 << 24


@dataclass(frozen=True, eq=False)
class SpeciationResult:
    """species [P] long ids; proto_ids [K] long (carried-over first, then new in founding order);
    proto_index [K] long prototype rows; next_species_id: the next unused id."""

    species: Tensor
    proto_ids: Tensor
    proto_index: Tensor
    next_species_id: int


def hamming(a: Tensor, b: Tensor) -> Tensor:
    """[Pa, L] bool, [Pb, L] bool -> [Pa, Pb] float32 Hamming distances (exact integer counts)."""
    af, bf = a.float(), b.float()
    return af @ (1.0 - bf).T + (1.0 - af) @ bf.T


def _one_hot_bt(bt: Tensor) -> Tensor:
    """[P, L] long opcodes -> [P, L * NUM_OPCODES] float32 one-hot."""
    oh = torch.zeros(*bt.shape, NUM_OPCODES, dtype=torch.float32, device=bt.device)
    oh.scatter_(-1, bt.long().unsqueeze(-1), 1.0)
    return oh.flatten(1)


def distance_terms(
    a: Population, b: Population, w: DistanceWeights = DistanceWeights()
) -> dict[str, Tensor]:
    """Genomes [Pa], [Pb] -> the weighted terms of D, each [Pa, Pb] float32, in the order of the
    sum: tag = w_tag (H/L)^gamma, hw = w_hw d_hw, bt = w_bt d_bt, tool = w_tool d_tool,
    size = w_size d_size.

    H: tag Hamming distance, L: tag length; d_hw: Euclidean distance of `hardware_vector()`
    / sqrt(its dimension), the two continuous operating points;
    d_bt: fraction of BT slots whose opcode differs; d_tool: effectors differ;
    d_size: |dr| / (R_MAX - R_MIN).
    """
    pa, pb = a.size, b.size
    dev = a.bt.device
    l_tag = a.tag.shape[1]
    if l_tag > 0:
        d_tag = (hamming(a.tag, b.tag) / l_tag) ** w.gamma
    else:
        d_tag = torch.zeros(pa, pb, device=dev)
    ha, hb = a.hardware_vector(), b.hardware_vector()
    d_hw = torch.cdist(ha, hb, compute_mode="donot_use_mm_for_euclid_dist") / math.sqrt(ha.shape[1])
    l_bt = a.bt.shape[1]
    if l_bt > 0:
        matches = _one_hot_bt(a.bt) @ _one_hot_bt(b.bt).T
        d_bt = 1.0 - matches / l_bt
    else:
        d_bt = torch.zeros(pa, pb, device=dev)
    d_tool = (a.effector[:, None] != b.effector[None, :]).float()
    d_size = (a.radius.float()[:, None] - b.radius.float()[None, :]).abs() / (R_MAX - R_MIN)
    return {
        "tag": w.w_tag * d_tag,
        "hw": w.w_hw * d_hw,
        "bt": w.w_bt * d_bt,
        "tool": w.w_tool * d_tool,
        "size": w.w_size * d_size,
    }


def distance(a: Population, b: Population, w: DistanceWeights = DistanceWeights()) -> Tensor:
    """Genomes [Pa], [Pb] -> [Pa, Pb] float32 D = w_tag (H/L)^gamma + w_hw d_hw + w_bt d_bt
    + w_tool d_tool + w_size d_size (the sum of `distance_terms`)."""
    t = distance_terms(a, b, w)
    return t["tag"] + t["hw"] + t["bt"] + t["tool"] + t["size"]


def design_distance(proto: Population, w: DistanceWeights = DistanceWeights()) -> Tensor:
    """Genomes [K] -> [K, K] float32: the hardware terms of D between them (w_hw d_hw + w_tool
    d_tool + w_size d_size), how far apart their robots are as designs. The tag (a signal for
    partner choice, not a property of the robot) and the tree are left out: which partner's
    robots are most like a species' robots (`partner_admission = "substitute"`)."""
    t = distance_terms(proto, proto, w)
    return t["hw"] + t["tool"] + t["size"]


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
    prototypes go to the earliest prototype in `proto_ids` order. Computed exactly in rounds
    (one per new species + 1), each a batched [P] update, not a loop over individuals; the [P, P]
    distance matrix is precomputed when P * P <= 2**24, else one [P, 1] column per round.
    """
    p = genome.size
    dev = genome.bt.device
    idx = torch.arange(p, device=dev)
    long_empty = torch.zeros(0, dtype=torch.long, device=dev)

    # (1) carry-over of surviving species.
    if prev_proto is not None and prev_proto_ids.numel() > 0 and p > 0:
        prev_ids = prev_proto_ids.to(dev).long()
        d_prev = distance(genome, prev_proto.to(dev), w)  # [P, Kp]
        member = species_hint.to(dev)[:, None] == prev_ids[None, :]  # [P, Kp]
        alive = member.any(0)
        closest = d_prev.masked_fill(~member, math.inf).argmin(0)  # first min = lowest row
        carried_rows, carried_ids = closest[alive], prev_ids[alive]
    else:
        carried_rows, carried_ids = long_empty, long_empty
    k = int(carried_rows.numel())

    assigned = torch.zeros(p, dtype=torch.bool, device=dev)
    assign_pos = torch.full((p,), -1, dtype=torch.long, device=dev)  # position in the proto list
    assigned[carried_rows] = True
    assign_pos[carried_rows] = torch.arange(k, device=dev)
    # Precompute all pairwise distances when that is cheap.
    full = distance(genome, genome, w) if 0 < p * p <= _FULL_MATRIX_MAX else None
    if k > 0:
        d_cur = (
            full[:, carried_rows]
            if full is not None
            else distance(genome, genome.index(carried_rows), w)
        )  # [P, Kc]
        arg = d_cur.argmin(1)
        min_d = d_cur.gather(1, arg[:, None]).squeeze(1)
    else:
        arg = torch.zeros(p, dtype=torch.long, device=dev)
        min_d = torch.full((p,), math.inf, device=dev)

    # (2) sequential founding, in rounds.
    new_rows: list[int] = []
    while p > 0:
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
        d_new = (
            full[:, f]
            if full is not None
            else distance(genome, genome.index(slice(f, f + 1)), w)[:, 0]
        )
        better = d_new < min_d  # strict: ties keep older
        arg = torch.where(better, torch.full_like(arg, k), arg)
        min_d = torch.where(better, d_new, min_d)
        k += 1
    assign_pos = torch.where(assigned, assign_pos, arg)

    n_new = len(new_rows)
    proto_ids = torch.cat(
        [
            carried_ids,
            torch.arange(next_species_id, next_species_id + n_new, dtype=torch.long, device=dev),
        ]
    )
    proto_index = torch.cat([carried_rows, torch.tensor(new_rows, dtype=torch.long, device=dev)])
    species = proto_ids[assign_pos] if p > 0 else long_empty
    return SpeciationResult(
        species=species,
        proto_ids=proto_ids,
        proto_index=proto_index,
        next_species_id=next_species_id + n_new,
    )
