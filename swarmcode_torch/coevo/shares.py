"""Each species' share of the next generation: the offspring quotas of `reproduction.quotas`
with the rules that keep a species alive whatever its fitness (the essential floor, the trial
floor of re-founded species, the best team's floor, equal shares early in a run). Step 3 of
`evolve.generation`, its first part; on the device, no host read."""

from __future__ import annotations

from dataclasses import replace

import torch
from torch import Tensor

from ..sim.tensors import cast
from . import knockout, refound
from .admission import Admission
from .config import ReproductionParams, SwarmCoDeConfig
from .evaluation import EvalResult
from .reproduction import Quotas, quotas
from .speciation import SpeciationResult


def plan(
    cfg: SwarmCoDeConfig,
    repro: ReproductionParams,
    sp: SpeciationResult,
    adm: Admission | None,
    fit: Tensor,
    trial: Tensor | None = None,
    equal: bool = False,
    best: Tensor | None = None,
    credit: Tensor | None = None,
    marginal: Tensor | None = None,
) -> Quotas:
    """Step 3 of a generation, its first part: each species' share of the next generation and its elites
    (`reproduction.quotas`), on the device. `trial` [K] bool: species founded by re-founding
    copies that keep their trial floor (`refound`). `equal` (`equal_quotas_until`): every
    species the same share, whatever its fitness and size. `best` [K] bool: the species of the
    generation's best team, which keep a floor of `best_team_floor`. `credit` [K] bool: the
    species credited by their knock-out from the best team (`knockout`), whose shares are those
    of the species of the highest mean fitness at their size, or, with `knockout_floor`, which
    keep that floor instead. `marginal` [P] (`share_basis` other than "fitness"): what the
    shares follow instead of `fit`, each individual's marginal contribution (at least 0), or
    `fit` plus it (`basis`)."""
    # 3. reproduction; essential species (partners that beat their baselines: they do a job no
    # partner does) keep a quota floor, so that a hard niche's holder is not starved out
    essential = priority = None
    if adm is not None and cfg.essential_floor > 0:
        priority = adm.gated[sp.proto_ids]
        essential = adm.partner[sp.proto_ids] & (priority < cfg.essential_below)
    if trial is not None:  # a trial species first, at a floor of at least the trial's
        essential = trial if essential is None else essential | trial
        priority = torch.where(trial, -1.0, 0.0 if priority is None else priority)
        floor = max(repro.essential_floor, refound.REFOUND.floor)
        repro = replace(repro, essential_floor=floor)
    floored = [(best, cfg.best_team_floor)]
    if credit is not None and cfg.knockout_floor > 0:  # a floor for the credited, no lift
        floored, credit = floored + [(credit, cfg.knockout_floor)], None
    for kept, at in floored:  # the best team's (or credited) species, after any trial species
        if kept is None:
            continue
        essential = kept if essential is None else essential | kept
        priority = torch.zeros(kept.numel(), device=kept.device) if priority is None else priority
        repro = replace(repro, essential_floor=max(repro.essential_floor, at))
    basis = fit if marginal is None else cast(marginal, torch.float)
    share = basis if credit is None else knockout.lift(basis, sp.species, sp.proto_ids, credit)
    if equal:  # the shares only: selection within a species still reads `fit`
        share, repro = torch.ones_like(fit), replace(repro, quota_size_exponent=0.0)
    q = quotas(share, sp.species, sp.proto_ids, repro, essential, priority, present=True)
    return q if share is fit else replace(q, fit=cast(fit, torch.float))


def best_team_species(res: EvalResult, sp: SpeciationResult, tie: float = 0.0) -> Tensor:
    """[K] bool: the species (of `sp.proto_ids`) with a robot in the generation's best team
    (`readout.best_index`'s at `tie`), on the device."""
    return knockout.team_has(knockout.best_team(res, tie), sp.species, sp.proto_ids)


def basis(share_basis: str, res: EvalResult, fit: Tensor) -> Tensor | None:
    """[P] what the offspring shares follow in place of `fit` (`share_basis`): each member's
    marginal contribution this generation (at least 0), that per slot its design fills in its
    focal team ("marginal/slot"), or `fit` plus the marginal; None: `fit`."""
    if share_basis == "fitness":
        return None
    marginal = (res.focal - res.baseline).clamp(min=0)
    if share_basis == "marginal/slot":
        return marginal / res.swarms.focal_slot.sum(1).clamp(min=1).to(marginal.dtype)
    return marginal if share_basis == "marginal" else fit + marginal
