"""Re-founding extinct partner species from an archive of their champions (`refound_after`).

A niche whose only holder starves out early stays empty for the rest of a run: nothing in the
population is near it any more, and mutation rarely walks back (issue 38's first failure). This
rule keeps the last champion (its member of the highest smoothed fitness) of every species that
dies while it is a *partner* in the admission's sense (`coevo.admission`: its members beat the
baselines in which the nearest partner design refills their slots, so it did a job no partner
did), and gives it a second life:

- **Archive.** Up to `capacity` champions of extinct partners, with the generation they died;
  a full archive replaces its oldest entry.
- **Re-founding.** Once an entry has been dead `refound_after` generations, `clones` offspring
  of the next generation (those of the least fit parents) are replaced by copies of it (the
  first exact, the others mutated), without a species hint: speciation puts them in a species
  within δ, or founds one. One entry a generation, the longest dead first; the entry leaves the
  archive.
- **Trial.** A species founded by the copies keeps a quota floor of `floor` slots for `trial`
  generations (exempt from `min_share`, as an essential species' floor), and is on probation as
  every new species is: admitted as a partner only if its members beat their baselines. A
  copy of a champion whose job another species now does stays gated, is never admitted and dies
  after its trial; a re-founded species that is admitted and dies again is archived again, up
  to `tries` re-foundings of one lineage.

With `refound_source = "designs"` the archive keeps designs, not partners: a species' champion
is archived on its death when it was the only champion of its *design cell* (its effector and
which of `size_bins` equal bands of the radius range its robots fall in), young or old, partner
or not; an entry replaces an older one of the same cell, and it is re-founded only while no
living species' champion is in its cell. This keeps a memory of every kind of robot the run
has had, including those of the first generations that did a hard job badly and starved before
any became a partner (issue 38's early lock-in).

With `refound_source = "random"` re-founding explores instead of remembering: every
`refound_after` generations (from generation `refound_after` on) the copies are of the
generation's best individual (its elite copy: the elite child of the fittest parent) with its
hardware genes (radius, effector, tiers, operating points) drawn as generation 0 draws them, one
design for every copy; its tree, tag, selectivity and dominance stay. A design the population
has lost, or never had, is tried with a tree that works, under the same trial (random
immigrants, Grefenstette 1992, with the best tree). The archive is kept but not re-founded
from.

It reads only what the algorithm has (fitness, species, admission, genomes); it knows no niche.
All of it runs on the device with shapes known on the host: it adds no host read to a
generation.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import torch
from torch import Tensor

from ..sim.hardware import R_MAX, R_MIN
from .population import HARDWARE_GENES, Population


@dataclass(frozen=True)
class RefoundParams:
    clones: int = 3
    trial: int = 10
    floor: int = 3
    tries: int = 2
    capacity: int = 8
    min_age: int = 5
    size_bins: int = 3  # with refound_source "designs": equal bands of the radius range


REFOUND = RefoundParams()


@dataclass(frozen=True, eq=False)
class Archive:
    """The rule's state. Archive slots [C]: genome, died (generation; -1: empty), tries (of
    the lineage). The champions of the last generation's species [K]: champ, champ_ids,
    champ_partner, champ_tries. By species id [N]: lineage (re-foundings before it),
    trial_until (the generation up to which it keeps its trial floor; -1: none), born (the
    generation it was founded). The copies
    put into the population to evaluate next: injected_rows [clones], injected (whether they
    are copies), injected_tries (their lineage's re-foundings)."""

    genome: Population
    died: Tensor
    tries: Tensor
    champ: Population
    champ_ids: Tensor
    champ_partner: Tensor
    champ_tries: Tensor
    lineage: Tensor
    trial_until: Tensor
    born: Tensor
    injected_rows: Tensor
    injected: Tensor
    injected_tries: Tensor

    # ------------------------------------------------------------------ state dicts
    _POP = ("genome", "champ")
    _TENSORS = (
        "died",
        "tries",
        "champ_ids",
        "champ_partner",
        "champ_tries",
        "lineage",
        "trial_until",
        "born",
        "injected_rows",
        "injected",
        "injected_tries",
    )

    def state_dict(self) -> dict:
        d: dict = {k: getattr(self, k).state_dict() for k in self._POP}
        d.update({k: getattr(self, k).detach().cpu() for k in self._TENSORS})
        return d

    @classmethod
    def from_state_dict(cls, d: dict, device: torch.device | str = "cpu") -> Archive:
        """ValueError unless d has every part, tensors of consistent sizes."""
        if not isinstance(d, dict) or set(d) != set(cls._POP) | set(cls._TENSORS):
            raise ValueError("checkpoint's re-founding archive is malformed")
        try:
            pops = {k: Population.from_state_dict(d[k]).to(device) for k in cls._POP}
        except (TypeError, ValueError, AttributeError):
            raise ValueError("checkpoint's re-founding archive is malformed") from None
        ts = {k: d[k] for k in cls._TENSORS}
        if not all(isinstance(t, Tensor) and t.dim() <= 1 for t in ts.values()):
            raise ValueError("checkpoint's re-founding archive is malformed")
        c, k = pops["genome"].size, pops["champ"].size
        sizes = {"died": c, "tries": c, "champ_ids": k, "champ_partner": k, "champ_tries": k}
        if any(ts[n].numel() != m for n, m in sizes.items()) or (
            ts["lineage"].numel() != ts["trial_until"].numel()
            or ts["lineage"].numel() != ts["born"].numel()
        ):
            raise ValueError("checkpoint's re-founding archive is malformed")
        tensors = {n: t.to(device) for n, t in ts.items()}
        return cls(genome=pops["genome"], champ=pops["champ"], **tensors)


def design_cell(pop: Population, bins: int) -> Tensor:
    """[P] long: each genome's design cell, effector * bins + the band of its radius among
    `bins` equal bands of [R_MIN, R_MAX]."""
    band = ((pop.radius.float() - R_MIN) / (R_MAX - R_MIN) * bins).floor().long()
    return pop.effector.long() * bins + band.clamp(0, bins - 1)


def _grow(t: Tensor, n: int, fill: int) -> Tensor:
    m = t.numel()
    return t if n <= m else torch.cat([t, t.new_full((n - m,), fill)])


def observe(
    arc: Archive | None,
    species: Tensor,
    proto_ids: Tensor,
    old_next_id: int,
    next_id: int,
    generation: int,
    params: RefoundParams = REFOUND,
    bins: int = 0,
) -> Archive | None:
    """After speciation: the species founded by last generation's copies start their trial; the
    champions of species that died since the last generation (absent from `proto_ids`) that
    were partners (`bins` > 0: the only champion of their design cell) go into the archive,
    by design cell over an entry of the same cell. None (no state yet) stays None."""
    if arc is None:
        return None
    lineage = _grow(arc.lineage, next_id, 0)
    trial_until = _grow(arc.trial_until, next_id, -1)
    born = _grow(arc.born, next_id, generation)
    # the copies' species, where the copies founded it this generation
    sid = species[arc.injected_rows]
    new = arc.injected & (sid >= old_next_id)
    target = torch.where(new, sid, next_id)  # next_id: a scratch slot
    lineage = torch.cat([lineage, lineage.new_zeros(1)]).scatter(
        0, target, arc.injected_tries.expand_as(sid)
    )[:next_id]
    trial_until = torch.cat([trial_until, trial_until.new_zeros(1)]).scatter(
        0, target, torch.full_like(sid, generation + params.trial - 1)
    )[:next_id]
    # the dead partners' champions, into the empty slots and then over the oldest entries
    dead = ~torch.isin(arc.champ_ids, proto_ids)
    keep = dead & arc.champ_partner & (arc.champ_tries < params.tries)
    c = arc.died.numel()
    dest = _slots(arc, keep, bins)
    k = arc.champ_ids.numel()
    src = torch.full((c + 1,), -1, dtype=torch.long, device=dest.device)
    src = src.scatter(0, dest, torch.arange(k, device=dest.device))[:c]
    fresh = src >= 0
    genome = arc.champ.index(src.clamp(min=0)).where(fresh, arc.genome)
    died = torch.where(fresh, generation, arc.died)
    tries = torch.where(fresh, arc.champ_tries[src.clamp(min=0)], arc.tries)
    return Archive(
        genome,
        died,
        tries,
        arc.champ,
        arc.champ_ids,
        arc.champ_partner,
        arc.champ_tries,
        lineage,
        trial_until,
        born,
        arc.injected_rows,
        torch.zeros_like(arc.injected),
        arc.injected_tries,
    )


def _slots(arc: Archive, keep: Tensor, bins: int) -> Tensor:
    """[K] long: the archive slot each kept champion goes to (C: none), the empty slots first,
    then the oldest; with `bins` > 0 the slot of an entry of its design cell, where there is
    one, and those slots are no one else's."""
    c = arc.died.numel()
    key = torch.where(arc.died < 0, torch.iinfo(torch.long).min, arc.died)
    fresh = keep
    limit: Tensor | int = c
    matched = None
    if bins > 0:
        held = arc.died >= 0
        cells = design_cell(arc.genome, bins)
        same = keep[:, None] & held[None, :] & (design_cell(arc.champ, bins)[:, None] == cells)
        taken, matched = same.any(0), same.any(1)
        key = torch.where(taken, torch.iinfo(torch.long).max, key)
        limit = c - taken.sum()
        fresh = keep & ~matched
    rank = fresh.long().cumsum(0) - 1
    slots = torch.sort(key, stable=True).indices
    dest = torch.where(fresh & (rank < limit), slots[rank.clamp(0, c - 1)], c)
    if matched is not None:
        dest = torch.where(matched, same.int().argmax(1), dest)
    return dest


def champions(
    arc: Archive | None,
    genome: Population,
    fitness: Tensor,
    species: Tensor,
    proto_ids: Tensor,
    partner: Tensor | None,
    next_id: int,
    generation: int,
    params: RefoundParams = REFOUND,
    bins: int = 0,
) -> Archive:
    """After evaluation: each species' champion (its member of the highest `fitness`), whether
    it would be archived on its death (`partner` [N] by species id, and founded `min_age`
    generations ago or more: a species of a few generations is noise of the search, not a job
    done; with `bins` > 0, `partner` unused: it is the only champion of its design cell, at any
    age) and its lineage's re-foundings. Starts the state (an empty archive) where `arc` is
    None."""
    dev = fitness.device
    k = proto_ids.numel()
    pos = (species[:, None] == proto_ids[None, :]).to(torch.int32).argmax(1).long()
    # the best member of each species: the highest fitness, the first row on ties
    order = torch.sort(fitness.float(), descending=True, stable=True).indices
    first = torch.full((k,), fitness.numel(), dtype=torch.long, device=dev)
    first = first.scatter_reduce(0, pos[order], torch.arange(order.numel(), device=dev), "amin")
    champ_row = order[first.clamp(max=max(order.numel() - 1, 0))]
    if arc is None:
        c = params.capacity
        arc = Archive(
            genome.index(torch.zeros(c, dtype=torch.long, device=dev)),
            torch.full((c,), -1, dtype=torch.long, device=dev),
            torch.zeros(c, dtype=torch.long, device=dev),
            genome.index(champ_row),
            proto_ids,
            torch.zeros(k, dtype=torch.bool, device=dev),
            torch.zeros(k, dtype=torch.long, device=dev),
            torch.zeros(next_id, dtype=torch.long, device=dev),
            torch.full((next_id,), -1, dtype=torch.long, device=dev),
            torch.full((next_id,), generation, dtype=torch.long, device=dev),
            torch.zeros(params.clones, dtype=torch.long, device=dev),
            torch.zeros((), dtype=torch.bool, device=dev),
            torch.zeros((), dtype=torch.long, device=dev),
        )
    lineage = _grow(arc.lineage, next_id, 0)
    born = _grow(arc.born, next_id, generation)
    champ = genome.index(champ_row)
    if bins > 0:
        cells = design_cell(champ, bins)
        archivable = (cells[:, None] == cells[None, :]).sum(1) == 1
    else:
        assert partner is not None
        archivable = partner[proto_ids] & (generation - born[proto_ids] >= params.min_age)
    return Archive(
        arc.genome,
        arc.died,
        arc.tries,
        champ,
        proto_ids,
        archivable,
        lineage[proto_ids],
        lineage,
        _grow(arc.trial_until, next_id, -1),
        born,
        arc.injected_rows,
        arc.injected,
        arc.injected_tries,
    )


def random_hardware(base: Population, generator: torch.Generator) -> Population:
    """`base` with its hardware genes drawn as `Population.random` draws them (generation 0),
    one design for every row. Draws the same numbers whatever `base` holds."""
    fresh = Population.random(1, base.tag.shape[1], base.bt[:1], generator, base.radius.device)
    drawn = fresh.index(torch.zeros(base.size, dtype=torch.long, device=base.radius.device))
    return replace(base, **{n: getattr(drawn, n) for n in HARDWARE_GENES})


def explorer(source: str, generator: torch.Generator) -> Callable[[Population], Population] | None:
    """`inject`'s `explore` of a run whose `refound_source` is `source`: `random_hardware` with
    the run's generator for "random"; None otherwise."""
    if source != "random":
        return None
    return lambda base: random_hardware(base, generator)


def on_trial(arc: Archive | None, proto_ids: Tensor, generation: int) -> Tensor | None:
    """[K] bool: the species proto_ids that keep their trial floor this generation."""
    if arc is None:
        return None
    return arc.trial_until[proto_ids] >= generation


def inject(
    arc: Archive,
    children: Population,
    hint: Tensor,
    parent_fitness: Tensor,
    is_elite: Tensor,
    generation: int,
    after: int,
    mutate,
    params: RefoundParams = REFOUND,
    bins: int = 0,
    explore: Callable[[Population], Population] | None = None,
) -> tuple[Archive, Population, Tensor]:
    """After reproduction: where an archive entry has been dead `after` generations, the
    `clones` offspring of the least fit parents become copies of it (the first exact, the
    others `mutate`d) with no species hint, and the entry leaves the archive. `mutate` is
    called on every generation, copies or not, so that the run's random stream does not depend
    on the archive. With `bins` > 0 an entry whose design cell a living species' champion holds
    waits. With `explore` (`explorer`), every `after` generations the copies are `explore` of
    the best elite child (the copy of the fittest parent), and the archive is not read;
    `explore` too is called every generation."""
    dev = hint.device
    m = min(params.clones, int(children.size))
    due = (arc.died >= 0) & (arc.died + after <= generation)
    if bins > 0:
        due = due & ~torch.isin(design_cell(arc.genome, bins), design_cell(arc.champ, bins))
    key = torch.where(due, arc.died, torch.iinfo(torch.long).max)
    pick = key.argmin()
    has = due.any()
    copies = arc.genome.index(pick.expand(m))
    if explore is not None:
        best = torch.where(is_elite, parent_fitness.float(), -torch.inf).argmax()
        copies = explore(children.index(best.expand(m)))
        has = torch.tensor(generation >= after and generation % after == 0, device=dev)
        has = has & is_elite.any()
    mutated = mutate(copies)
    first = torch.arange(m, device=dev) == 0
    copies = copies.where(first, mutated)
    # the offspring of the least fit parents (never an elite)
    score = torch.where(is_elite, torch.inf, parent_fitness.float())
    rows = torch.sort(score, stable=True).indices[:m]
    put = torch.zeros(children.size, dtype=torch.bool, device=dev).scatter(0, rows, has.expand(m))
    src = torch.zeros(children.size, dtype=torch.long, device=dev).scatter(
        0, rows, torch.arange(m, device=dev)
    )
    children = copies.index(src).where(put, children)
    hint = torch.where(put, -1, hint)
    leaves = has & (explore is None)  # an explorer takes no entry from the archive
    died = torch.where(leaves & (torch.arange(arc.died.numel(), device=dev) == pick), -1, arc.died)
    return (
        Archive(
            arc.genome,
            died,
            arc.tries,
            arc.champ,
            arc.champ_ids,
            arc.champ_partner,
            arc.champ_tries,
            arc.lineage,
            arc.trial_until,
            arc.born,
            rows,
            has,
            arc.tries[pick] + 1,
        ),
        children,
        hint,
    )
