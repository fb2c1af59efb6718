"""Partner admission from the gate's own statistics (`partner_admission = "substitute"`).

The paper's partner rule makes every species that the tags accept a partner of everyone, the
moment it is founded. Two species that can stand in for each other (a niche's resident R and a
new duplicate D) are then in each other's teams and refill each other's slots in each other's
baselines, so the marginal gate credits both alike and neither is selected against. This rule
breaks that tie with what evaluation measures, nothing else (no scenario, no capability); every
focal's baseline re-fills its slots from its nearest partner design
(`speciation.design_distance`, `nearest_partner`):

- **Probation.** A species founded after generation 0 is no one's partner until the moving
  average of its gated share (the fraction of its members whose focal team did not beat its
  baseline) has stayed below `admit_below` for `admit_generations` generations in a row. On
  probation its own team still holds every partner, so a duplicate, whose robots the resident
  replaces at no loss, stays gated and is never admitted; a species that does what no partner
  does beats its baseline and is admitted.
- **Demotion.** A partner whose gated share has been above `clash_above` for
  `clash_generations` generations in a row is a substitute of its nearest partner when that
  partner's design is within the speciation threshold δ of its own (the hardware terms of D:
  the two would be one species but for their tags and trees), and the lower-ranked of the two
  (the smaller, then the younger) stops being a partner and is on probation again; at most one
  a generation. A partner gated as often whose nearest partner is a different design is not a
  substitute: it does a job no partner does that does not pay yet (early in a run most
  species are gated half the time), and demoting it would lose its niche.

The state is kept by species id (`Admission`), saved in checkpoints.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor

from ..sim.tensors import arange, cast
from .population import Population
from .speciation import DistanceWeights, design_distance


@dataclass(frozen=True)
class AdmissionParams:
    """Thresholds of the rule. A species whose robots its nearest partner can replace at no
    loss is gated about half the time (its marginal contribution is zero up to noise), one that
    does what no partner does far less often: a probationer is admitted only when clearly below
    one half, and a partner gated half the time or more is a substitute of its nearest partner."""

    admit_below: float = 0.3
    admit_generations: int = 3
    clash_above: float = 0.5
    clash_generations: int = 2
    decay: float = 0.5  # weight of the previous value in the moving average


@dataclass(frozen=True, eq=False)
class Admission:
    """Per species id (0 .. N-1): partner [N] bool, gated [N] float (moving average of the gated
    share; NaN before its first evaluation), calm [N] long (generations in a row below
    `admit_below` while on probation), clash [N] long (generations in a row above
    `clash_above` while a partner)."""

    partner: Tensor
    gated: Tensor
    calm: Tensor
    clash: Tensor

    @classmethod
    def empty(cls, device: torch.device | str = "cpu") -> Admission:
        return cls(
            torch.zeros(0, dtype=torch.bool, device=device),
            torch.zeros(0, device=device),
            torch.zeros(0, dtype=torch.long, device=device),
            torch.zeros(0, dtype=torch.long, device=device),
        )

    def grow(self, n: int, partner: bool) -> Admission:
        """Room for species ids below n; ids new to it start as partners if `partner` (the
        species of generation 0), else on probation."""
        m = self.partner.numel()
        if n <= m:
            return self
        new = (0, n - m)  # padding at the end
        return Admission(
            F.pad(self.partner, new, value=partner),
            F.pad(self.gated, new, value=torch.nan),
            F.pad(self.calm, new),
            F.pad(self.clash, new),
        )

    def allowed(self, proto_ids: Tensor) -> Tensor:
        """[K] bool: which of the species proto_ids may be partners."""
        return self.partner[proto_ids]

    def state_dict(self) -> dict:
        return {
            "partner": self.partner.cpu(),
            "gated": self.gated.cpu(),
            "calm": self.calm.cpu(),
            "clash": self.clash.cpu(),
        }

    @classmethod
    def from_state_dict(cls, d: dict, device: torch.device | str = "cpu") -> Admission:
        """ValueError unless d holds four 1-D tensors of one length and the right dtypes."""
        want = {
            "partner": torch.bool,
            "gated": torch.float32,
            "calm": torch.long,
            "clash": torch.long,
        }
        if not isinstance(d, dict) or set(d) != set(want):
            raise ValueError("checkpoint's partner admission state is malformed")
        n = None
        for k, dt in want.items():
            t = d[k]
            if (
                not isinstance(t, Tensor)
                or t.dtype != dt
                or t.dim() != 1
                or (n is not None and t.numel() != n)
            ):
                raise ValueError("checkpoint's partner admission state is malformed")
            n = t.numel()
        return cls(*(d[k].to(device) for k in want))


#: The thresholds of `partner_admission = "substitute"`.
SUBSTITUTE = AdmissionParams()


def effector_first(design_distance: Tensor, effector: Tensor, on: bool = True) -> Tensor:
    """design_distance [K, K], effector [K] -> [K, K]: where `on` (`substitute_effector`), every
    pair of differing effectors farther than any pair of one effector (the same order within
    each), so that a species' nearest partner is of its own effector where it has one and never
    within δ of another; else `design_distance` as it is."""
    if not on or design_distance.numel() == 0:
        return design_distance
    differ = effector[:, None] != effector[None, :]
    return torch.where(differ, design_distance + design_distance.max() + 1, design_distance)


def designs(proto: Population, w: DistanceWeights, by_effector: bool) -> Tensor:
    """[K, K]: the distances the admission reads between the designs of the prototypes `proto`
    (`speciation.design_distance`), effector first where `by_effector` (`effector_first`)."""
    return effector_first(design_distance(proto, w), proto.effector, by_effector)


def nearest_partner(design_distance: Tensor, allowed: Tensor) -> Tensor:
    """design_distance [K, K], allowed [K] bool -> [K] long: for each species the index of the
    allowed species (other than itself) whose design is nearest (the first of equals), -1 where
    there is none."""
    k = allowed.numel()
    eye = torch.eye(k, dtype=torch.bool, device=allowed.device)
    d = torch.where(allowed & ~eye, cast(design_distance, torch.float), torch.inf)
    nearest = d.min(1)  # the first of equals, as argmin
    return torch.where(torch.isfinite(nearest.values), nearest.indices, -1)


def near_partner(design_distance: Tensor, nearest: Tensor, delta: float) -> Tensor:
    """design_distance [K, K], nearest [K] (`nearest_partner`) -> [K] bool: the nearest
    partner's design is within delta of the species' own (where there is none: of the first
    species', which no one reads)."""
    k = nearest.numel()
    return design_distance[arange(k, nearest.device), nearest.clamp_min(0)] <= delta


def same_effector(effector: Tensor, nearest: Tensor) -> Tensor:
    """effector [K] (the prototypes'), nearest [K] (`nearest_partner`) -> [K] bool: the nearest
    partner's robots have the species' effector (False where there is none)."""
    return (nearest >= 0) & (effector == effector[nearest.clamp_min(0)])


def update(
    adm: Admission,
    species: Tensor,
    proto_ids: Tensor,
    gated: Tensor,
    nearest: Tensor,
    params: AdmissionParams = AdmissionParams(),
    near: Tensor | None = None,
    elite: Tensor | None = None,
) -> Admission:
    """The admission after one evaluation: species [P] ids, proto_ids [K] (the species, in
    order of founding), gated [P] bool (whose focal team did not beat its baseline), nearest [K]
    long (`nearest_partner`, the partner each species' baseline was re-filled from), near [K]
    bool (its design is within δ of that partner's; None: every pair is near): a partner above
    `clash_above` for `clash_generations` whose nearest partner is near is a substitute of it,
    and the lower-ranked of the two is demoted. `elite` [P] bool (None: no one): a species'
    gated share is that of its elites, the members carried over unchanged, where it has any
    (its fresh offspring, some of them broken by mutation, would blur what the species does),
    else that of all its members."""
    k = proto_ids.numel()
    if k == 0:
        return adm
    member = species[:, None] == proto_ids  # [P, K]
    size = member.sum(0)
    share = (member & gated[:, None]).sum(0) / size.clamp_min(1)  # counts: a float32 quotient
    if elite is not None:
        kept = member & elite[:, None]
        n_kept = kept.sum(0)
        kept_share = (kept & gated[:, None]).sum(0) / n_kept.clamp_min(1)
        share = torch.where(n_kept > 0, kept_share, share)
    prev = adm.gated[proto_ids]
    avg = torch.where(torch.isnan(prev), share, params.decay * prev + (1 - params.decay) * share)
    partner = adm.partner[proto_ids]
    calm = torch.where(~partner & (avg < params.admit_below), adm.calm[proto_ids] + 1, 0)
    clash = torch.where(partner & (avg > params.clash_above), adm.clash[proto_ids] + 1, 0)
    admit = ~partner & (calm >= params.admit_generations)
    clashing = clash >= params.clash_generations
    rank = size * (proto_ids.max() + 1) - proto_ids  # higher: larger, then older
    pair = clashing & (nearest >= 0)
    if near is not None:
        pair = pair & near
    # the lowest-ranked loser of a clashing pair, if any (no value is read on the host: where
    # there is no pair, no one is demoted)
    idx = arange(k, rank.device)
    other = nearest.clamp_min(0)
    loser = torch.where(rank[other] < rank, other, idx)
    low = torch.where(pair, rank[loser], rank.max() + 1)
    demote = (idx == loser.take(low.argmin())) & pair.any()
    new_partner = (partner | admit) & ~demote
    reset = admit | demote
    at = (proto_ids,)
    out = Admission(
        adm.partner.index_put(at, new_partner),
        adm.gated.index_put(at, avg),
        adm.calm.index_put(at, torch.where(reset, 0, calm)),
        adm.clash.index_put(at, torch.where(reset, 0, clash)),
    )
    return out
