"""Partner choice and swarm assembly: the composition step of the cooperative evaluation."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor

from ..sim.tensors import arange, cast
from .selection import elite_count, group_sizes, rank_within_groups, top_table
from .speciation import hamming


@dataclass(frozen=True, eq=False)
class Swarms:
    """Teams of B evaluations with S slots (population rows; -1 = empty slot).

    focal_team [B, S], baseline_team [B, S], focal_species_count [B] (1 + partners in the team),
    baseline_species_count [B] (partners in the team), focal_slot [B, S] bool (slots of the focal
    design in focal_team = the slots re-filled in baseline_team), partner_in_team [B, K] bool.
    """

    focal_team: Tensor
    baseline_team: Tensor
    focal_species_count: Tensor
    baseline_species_count: Tensor
    focal_slot: Tensor
    partner_in_team: Tensor


def choose_partners(
    tag: Tensor,
    selectivity: Tensor,
    species: Tensor,
    proto_ids: Tensor,
    proto_tag: Tensor,
    elite_index: Tensor,
    generator: torch.Generator,
    allowed: Tensor | None = None,
    always: Tensor | None = None,
) -> Tensor:
    """tag [P, L] bool, selectivity [P], species [P], proto_ids [K], proto_tag [K, L],
    elite_index [K, M] -> partner_rows [P, K] long.

    Species k is a partner of i iff it is not i's species, has >= 1 elite, and
    H(tag_i, proto_tag_k)/L < selectivity_i (strict) or `always[k]` where that [K] bool mask is
    given (`team_partner_mask`), and `allowed[k]` where that [K] bool mask is given
    (`niche_representatives`); partner_rows[i, k] is one of k's elites drawn uniformly, else -1.
    The random draws do not depend on `allowed` or `always`.
    """
    p, l = tag.shape
    k = proto_ids.numel()
    dev = tag.device
    if k == 0 or p == 0 or elite_index.shape[1] == 0:
        return torch.full((p, k), -1, dtype=torch.long, device=dev)
    dist = hamming(tag, cast(proto_tag, device=dev)) / max(l, 1)  # [P, K]
    valid = elite_index >= 0
    count = valid.sum(1)  # [K]
    chosen = dist < selectivity[:, None]
    if always is not None:
        chosen |= cast(always, device=dev)
    eligible = chosen & (species[:, None] != proto_ids) & (count > 0)
    if allowed is not None:
        eligible &= cast(allowed, device=dev)
    # left-pack each species' elites so that entries 0..count-1 are valid
    packed = elite_index.gather(1, torch.sort((~valid).to(torch.uint8), dim=1, stable=True).indices)
    u = torch.rand(p, k, generator=generator, device=dev)
    j = torch.minimum((u * count).long(), (count - 1).clamp(min=0))  # [P, K] the elite drawn
    rows = packed.T.gather(0, j)  # rows[i, k] = packed[k, j[i, k]]
    return torch.where(eligible, rows, -1)


def team_partner_mask(history: list, proto_ids: Tensor) -> Tensor | None:
    """[K] bool: the species of `proto_ids` with a robot in the last best team of `history` (the
    generations' composition records, `{"team": {species id: robots}}`), or of its `needed` list
    of species ids where the record has one (`team_partners_margin`); None before the first
    generation (`team_partners`)."""
    if not history:
        return None
    last = history[-1]
    ids = [int(s) for s in last.get("needed", last["team"])]
    return torch.isin(proto_ids, torch.tensor(ids, dtype=proto_ids.dtype, device=proto_ids.device))


def ranking_fitness(fitness: Tensor, has_fitness: Tensor) -> Tensor:
    """[P] float fitness by which elites rank: -inf where there is none (or it is NaN)."""
    return torch.where(
        has_fitness, torch.nan_to_num(cast(fitness, torch.float), nan=-torch.inf), -torch.inf
    )


def niche_representatives(
    capability: Tensor, sizes: Tensor, best: Tensor, has_elite: Tensor
) -> Tensor:
    """capability [K, U] bool (the package classes each species' design can lift), sizes [K],
    best [K] (its fittest elite's fitness, -inf for none), has_elite [K] bool -> [K] bool: the
    species that may be partners when each niche gives one.

    Species that lift the same non-empty set of classes share a niche; of those with an elite,
    the representative is the largest, then the one with the fittest elite, then the first
    (the oldest: species are in order of founding). A species that lifts nothing, and one
    alone in its niche, represents itself; a species without an elite represents nothing."""
    k = sizes.numel()
    same = (capability[:, None, :] == capability[None, :, :]).all(-1)  # [K, K]
    same &= capability.any(-1)[:, None]
    idx = torch.arange(k, device=sizes.device)
    size, fit = sizes[:, None], best[:, None]
    earlier = idx[None, :] < idx[:, None]  # [k, j]: j comes first
    beats = (size.T > size) | ((size.T == size) & ((fit.T > fit) | ((fit.T == fit) & earlier)))
    beaten = (same & beats & has_elite[None, :]).any(1)  # [k, j]: j beats k
    return has_elite & ~beaten


def elite_rows(
    fitness: Tensor,
    has_fitness: Tensor,
    species: Tensor,
    proto_ids: Tensor,
    n_elite_fn: Callable[[Tensor], Tensor] = elite_count,
    width: int | None = None,
) -> Tensor:
    """fitness [P], has_fitness [P] bool, species [P], proto_ids [K] -> [K, M] long elite rows
    per species, best first, -1 padded; M = `width` where given (a bound of n_elite_fn: no value
    is then read on the host), else the largest N_k.

    N_k = n_elite_fn(sizes [K] long) (capped by the size); individuals without fitness rank below
    those with it; ties by lowest row; individuals whose species is not in proto_ids are ignored.
    """
    k = proto_ids.numel()
    dev = fitness.device
    if k == 0:
        return torch.full((0, 0), -1, dtype=torch.long, device=dev)
    match = species[:, None] == proto_ids
    pos = torch.where(match.any(1), match.to(torch.int32).argmax(1), k)  # k: not in any species
    sizes = group_sizes(pos, k + 1)
    species_sizes = sizes[:k]  # (sizes[k]: no species)
    n_wanted = cast(n_elite_fn(species_sizes), torch.long, dev)
    f = ranking_fitness(fitness, has_fitness)
    order, rank = rank_within_groups(pos, f, sizes, first=has_fitness)
    return top_table(order, rank, pos, torch.minimum(n_wanted, species_sizes), width)


def assemble_swarms(
    focal: Tensor,
    partner_rows: Tensor,
    dominance: Tensor,
    swarm_size: int,
    generator: torch.Generator,
    refill_distance: Tensor | None = None,
) -> Swarms:
    """focal [B] rows, partner_rows [B, K] (-1 none), dominance [P] -> Swarms of swarm_size S slots.

    Slot 0: the focal design; slots 1..: one per partner in the team (in species order; a uniform
    random subset of S - 1 if there are more partners); remaining slots: clones drawn from {focal,
    partners in the team} with probability proportional to dominance (uniform if all are 0).
    The baseline team re-fills every focal slot by dominance among the partners in the team
    (-1 if there are none); where `refill_distance` [B, K] float is given, only from the partner
    in the team at the least distance (the first of equals): the focal's slots are all given to
    its nearest partner species.
    """
    b, k = partner_rows.shape
    s = int(swarm_size)
    dev = partner_rows.device
    focal = cast(focal, torch.long, dev)
    dom = cast(dominance, torch.float).clamp(min=0.0)
    valid = partner_rows >= 0

    # uniform random subset of at most S - 1 partners: rank partners by random keys (the rank of
    # each: the inverse of the sorting permutation)
    keys = torch.where(valid, torch.rand(b, k, generator=generator, device=dev), 2.0)
    rank = torch.sort(keys, dim=1, stable=True).indices.argsort(1)
    in_team = valid & (rank < s - 1)
    n_team = in_team.sum(1)

    # the focal design, then the partners in the team, each in its slot; column s: discard bin
    cand = torch.cat([focal[:, None], torch.where(in_team, partner_rows, -1)], 1)  # [B, 1 + K]
    placed = F.pad(in_team, (1, 0), value=True)
    slot = torch.where(placed, placed.cumsum(1) - 1, s)
    team = torch.full((b, s + 1), -1, dtype=torch.long, device=dev).scatter_(1, slot, cand)[:, :s]

    cand_ok = cand >= 0
    w = torch.where(cand_ok, dom[cand.clamp(min=0)], 0.0)
    w = torch.where(w.sum(1, keepdim=True) > 0, w, cand_ok.float())
    draw = torch.multinomial(w, s, replacement=True, generator=generator)  # [B, S]
    empty = team < 0
    focal_team = torch.where(empty, cand.gather(1, draw), team)
    focal_slot = (empty & (draw == 0)) | (arange(s, dev) == 0)  # and slot 0, the focal's own

    refill = in_team
    if refill_distance is not None and k > 0:
        d = torch.where(refill, cast(refill_distance, torch.float, dev), torch.inf)
        nearest = arange(k, dev) == d.argmin(1, keepdim=True)
        refill = refill & nearest
    has_p = refill.any(1, keepdim=True)
    if k > 0:
        pw = torch.where(refill, dom[partner_rows.clamp(min=0)], 0.0)
        pw = torch.where(pw.sum(1, keepdim=True) > 0, pw, refill.float())
        pw = torch.where(has_p, pw, 1.0)  # dummy rows, masked below
        bdraw = torch.multinomial(pw, s, replacement=True, generator=generator)
        brows = torch.where(has_p, partner_rows.gather(1, bdraw), -1)
    else:
        brows = torch.full((b, s), -1, dtype=torch.long, device=dev)
    baseline_team = torch.where(focal_slot, brows, focal_team)
    return Swarms(
        focal_team=focal_team,
        baseline_team=baseline_team,
        focal_species_count=n_team + 1,
        baseline_species_count=n_team,
        focal_slot=focal_slot,
        partner_in_team=in_team,
    )
