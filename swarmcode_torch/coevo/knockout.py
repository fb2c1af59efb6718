"""Knock-out credit (`knockout_credit`, off by default): a species the best team needs is paid
as the best species is, whatever its own focal teams score.

A species is paid by its own focal teams, in which its design fills the slots the dominance
draw gives it; a specialist that does one hard job fills many, and those teams score low, so
the holder of a hard niche can starve while the best team needs it. Each generation this
module evaluates the generation's best team again beside one knock-out team per species (that
species' slots re-filled by robots drawn from the team's other slots), all on the same fresh
environments, and credits a species whose knock-out costs the team more than a margin: the
difference reward G(z) - G(z_-i) of multi-agent credit assignment (Wolpert and Tumer), taken
on the best team. A substitute's slots go to the species doing the same job, its knock-out
costs nothing, and it gets no credit. A credited species' share of the next generation is
that of a species with the highest species mean fitness at its size (`lift`); selection
within species still reads fitness. Reads scores only: no package class, capability or niche.

With `team_partners_margin` the same knock-outs choose which of the best team's species are
team partners of the next generation (`needed_ids`).

Demotion of substitute pairs (`knockout_pairs`, off by default) reads the same knock-outs the
other way: two species of the best team that each cost nothing when knocked out alone (each
one's slots go to the other) but a lot when knocked out together do one job twice, however far
apart their designs; the lower-ranked stops being a partner (`demote_substitutes`), as the
admission demotes a substitute within δ (`coevo.admission`). A substitute pair of Wiegand's
and Panait's cooperative coevolution, found by the difference reward of the pair.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import torch
from torch import Tensor

from ..sim import bt
from ..sim.hardware import Phenotype
from ..sim.layout import make_layouts
from ..sim.scenario import Scenario
from ..sim.state import WorldParams
from ..sim.tensors import arange
from .admission import Admission
from .config import EvalConfig
from .evaluation import EvalResult, ScoreFn, _scores, simulate_teams, team_scores
from .fitness import team_cost
from .population import Population, genome_phenotype
from .readout import best_index
from .selection import group_sizes
from .speciation import SpeciationResult


def best_team(res: EvalResult, tie: float = 0.0) -> Tensor:
    """[S] population rows of the generation's best team, `readout.best_index`'s at `tie`: the
    focal team of the individual of the highest gated fitness (by default)."""
    return res.swarms.focal_team[best_index(res, tie)[0]]


def slot_species(teams: Tensor, species: Tensor) -> Tensor:
    """teams [..., S] population rows (-1 empty), species [P] -> [..., S]: each slot's species
    (-1 where empty)."""
    return torch.where(teams >= 0, species[teams.clamp(min=0)], -1)


def team_has(team: Tensor, species: Tensor, proto_ids: Tensor) -> Tensor:
    """team [S] -> [K] bool: the species of `proto_ids` with a robot in the team."""
    return torch.isin(proto_ids, slot_species(team, species))


def knocked_out(
    team: Tensor, species: Tensor, proto_ids: Tensor, out: Tensor, generator: torch.Generator
) -> tuple[Tensor, Tensor]:
    """team [S] population rows (-1 empty), species [P], proto_ids [K], out [R, K] bool (the
    species each row knocks out) -> (teams [R, S], left [R] bool). Row r is the team with every
    slot of the species of out[r] re-filled by a robot drawn uniformly from the team's other
    filled slots (all -1, and left False, where the team has no other)."""
    s, r = team.numel(), out.shape[0]
    filled = team >= 0
    hit = ((slot_species(team, species)[:, None] == proto_ids) & out[:, None, :]).any(2)  # [R, S]
    keep = filled[None, :] & ~hit
    other = keep.any(1, keepdim=True)
    w = torch.where(other, keep.float(), 1.0)  # dummy weights where nothing is left
    draw = torch.multinomial(w, s, replacement=True, generator=generator) if r else w.long()
    refill = torch.where(other, team[draw], -1)
    return torch.where(hit, refill, team[None, :].expand(r, s)), other.squeeze(1)


def knockout_teams(
    team: Tensor, species: Tensor, proto_ids: Tensor, generator: torch.Generator
) -> tuple[Tensor, Tensor]:
    """team [S] population rows (-1 empty), species [P], proto_ids [K] -> (teams [K + 1, S],
    in_team [K] bool). Row 0 is the team; row 1 + k the team with every slot of species k
    re-filled by a robot drawn uniformly from the team's other filled slots (all -1 where the
    team has no other); a species not in the team leaves its row equal to the team."""
    k = proto_ids.numel()
    eye = torch.eye(k, dtype=torch.bool, device=team.device)
    teams, _ = knocked_out(team, species, proto_ids, eye, generator)
    return torch.cat([team[None, :], teams]), team_has(team, species, proto_ids)


def team_species_count(teams: Tensor, species: Tensor, proto_ids: Tensor) -> Tensor:
    """teams [R, S] -> [R] long: the number of distinct species with a robot in each team."""
    return (slot_species(teams, species)[:, :, None] == proto_ids).any(1).sum(1)


def team_scores_on_shared_layouts(
    teams: Tensor,
    genome: Population,
    species: Tensor,
    proto_ids: Tensor,
    scenario: Scenario,
    cfg: EvalConfig,
    generator: torch.Generator,
    params: WorldParams,
    step_fn=None,
    score_fn: ScoreFn = team_scores,
    phenotype: Phenotype | None = None,
) -> Tensor:
    """teams [R, S] -> [R] each team's mean score over `cfg.trials` fresh environments, the same
    environments for every team (drawn from `generator`), scored as evaluation scores (cost,
    budget penalty, `score_fn`)."""
    r, s = teams.shape
    t = cfg.trials
    dev = teams.device
    ph = phenotype if phenotype is not None else genome_phenotype(genome, scenario.hardware)
    layouts = make_layouts(replace(scenario, num_robots=s), t, generator, dev)
    m = simulate_teams(
        teams.repeat_interleave(t, 0),
        genome,
        bt.build_tables(genome.bt),
        arange(t, dev).repeat(r),
        layouts,
        params,
        cfg.ticks,
        step_fn,
        scenario.hardware,
        ph,
    )
    counts = team_species_count(teams, species, proto_ids)
    cost = team_cost(ph.cost[teams.clamp_min(0)], teams >= 0, counts, scenario.species_overhead)
    scores = _scores(score_fn, m, cost.repeat_interleave(t), cfg)
    return scores.view(r, t).mean(1)


def credited(scores: Tensor, in_team: Tensor, margin: float) -> Tensor:
    """scores [K + 1] (the team, then each knock-out) , in_team [K] bool -> [K] bool: the
    species of the team whose knock-out lowers the team's score by more than `margin` times
    its magnitude."""
    return in_team & (scores[0] - scores[1:] > margin * scores[0].abs())


def lift(fit: Tensor, species: Tensor, proto_ids: Tensor, credit: Tensor) -> Tensor:
    """fit [P], species [P], proto_ids [K] (every individual's species listed), credit [K] bool
    -> [P] the shares' fitness: each credited species' members raised by one amount, so that
    its mean is the highest species mean (no change where it already is); others as `fit`."""
    k = proto_ids.numel()
    pos = (species[:, None] == proto_ids).to(torch.int32).argmax(1)
    f = fit.float()
    mean = torch.zeros(k, device=f.device).index_add_(0, pos, f) / group_sizes(pos, k).clamp(min=1)
    raise_by = torch.where(credit, (mean.max() - mean).clamp(min=0), 0.0)
    return f + raise_by[pos]


def _run_scores(
    teams: Tensor, genome: Population, sp: SpeciationResult, phenotype: Phenotype, ctx: Any, g
) -> Tensor:
    """`team_scores_on_shared_layouts` of `teams` with the run's scenario, evaluation config,
    world, tick and score function (`ctx`, the run's `evolve.Context`)."""
    return team_scores_on_shared_layouts(
        teams,
        genome,
        sp.species,
        sp.proto_ids,
        ctx.scenario,
        ctx.eval_cfg,
        g,
        ctx.params,
        ctx.step_fn,
        ctx.score_fn,
        phenotype,
    )


def best_team_credit(
    res: EvalResult,
    sp: SpeciationResult,
    genome: Population,
    phenotype: Phenotype,
    ctx: Any,
    g,
    margin: float | None = None,
) -> Tensor:
    """[K] bool: the species of `sp.proto_ids` credited this generation (`credited` at `margin`,
    by default `ctx.cfg.knockout_credit`), from the best team of `res` (`best_team`'s, at
    `ctx.cfg.best_team_tie`) and its knock-outs, scored on fresh environments drawn from `g`.
    `ctx`: the run's `evolve.Context` (its scenario, evaluation config, world, tick and score
    function)."""
    teams, in_team = knockout_teams(
        best_team(res, ctx.cfg.best_team_tie), sp.species, sp.proto_ids, g
    )
    scores = _run_scores(teams, genome, sp, phenotype, ctx, g)
    return credited(scores, in_team, ctx.cfg.knockout_credit if margin is None else margin)


def needed_ids(
    res: EvalResult, sp: SpeciationResult, genome: Population, phenotype: Phenotype, ctx: Any, g
) -> list[int]:
    """The ids of the best team's species whose knock-out costs the team more than
    `ctx.cfg.team_partners_margin` of its score (`best_team_credit`): the next generation's
    team partners (`partners.team_partner_mask`). A species that another of the team stands in
    for (in a world where every complete team delivers everything, any second species of the
    one job) costs nothing and is not among them. Read on the host."""
    credit = best_team_credit(res, sp, genome, phenotype, ctx, g, ctx.cfg.team_partners_margin)
    return [int(i) for i in sp.proto_ids[credit].tolist()]


def substitute_pairs(scores: Tensor, m: int, left: Tensor, margin: float) -> Tensor:
    """scores [1 + m + m(m-1)/2] (the team, each of its m species knocked out, then each pair
    (i, j), i < j, in `torch.combinations` order), left [m(m-1)/2] bool (the pair's knock-out
    left robots in the team) -> [m(m-1)/2] bool: the pairs whose knock-outs each cost the team
    at most `margin` times its score while their joint knock-out costs more: two species that
    stand in for each other."""
    limit = margin * scores[0].abs()
    single = scores[0] - scores[1 : 1 + m] <= limit
    ij = torch.combinations(arange(m, scores.device), 2)
    joint = scores[0] - scores[1 + m :] > limit
    return single[ij[:, 0]] & single[ij[:, 1]] & joint & left


def demote_substitutes(
    adm: Admission | None,
    res: EvalResult,
    sp: SpeciationResult,
    genome: Population,
    phenotype: Phenotype,
    ctx: Any,
    g: torch.Generator,
) -> Admission | None:
    """The admission (`coevo.admission.Admission`) after `knockout_pairs`' test of the best team
    (the focal team of the highest gated fitness of `res`): of the pairs of its species that
    stand in for each other (`substitute_pairs`, on fresh environments drawn from `g`), the
    lowest-ranked member (the smaller, then the younger) of any pair stops being a partner and
    is on probation again (`admission.update`'s demotion), if it is a partner; at most one a
    generation. `adm` unchanged where the setting is 0 or admission is open. Reads on the host
    which species are in the team (one value a generation, with the setting on)."""
    margin = ctx.cfg.knockout_pairs
    if adm is None or margin <= 0:
        return adm
    team = best_team(res, ctx.cfg.best_team_tie)
    idx = team_has(team, sp.species, sp.proto_ids).nonzero().squeeze(1)
    m = idx.numel()  # the host read
    if m < 2:
        return adm
    dev = team.device
    ij = torch.combinations(arange(m, dev), 2)
    out = torch.zeros(m + ij.shape[0], sp.proto_ids.numel(), dtype=torch.bool, device=dev)
    rows = arange(m, dev)
    out[rows, idx] = True
    pair_rows = arange(ij.shape[0], dev) + m
    out[pair_rows, idx[ij[:, 0]]] = True
    out[pair_rows, idx[ij[:, 1]]] = True
    teams, left = knocked_out(team, sp.species, sp.proto_ids, out, g)
    scores = _run_scores(torch.cat([team[None, :], teams]), genome, sp, phenotype, ctx, g)
    pairs = substitute_pairs(scores, m, left[m:], margin)
    ids = sp.proto_ids[idx]
    size = (sp.species[:, None] == ids).sum(0)
    rank = size * (sp.proto_ids.max() + 1) - ids  # higher: larger, then older
    loser = torch.where(rank[ij[:, 0]] < rank[ij[:, 1]], ij[:, 0], ij[:, 1])
    low = torch.where(pairs, rank[loser], rank.max() + 1)
    who = ids[loser[low.argmin()]]
    demote = pairs.any() & adm.partner[who]
    at = (who[None],)
    return replace(
        adm,
        partner=adm.partner.index_put(at, (adm.partner[who] & ~demote)[None]),
        calm=adm.calm.index_put(at, torch.where(demote, 0, adm.calm[who])[None]),
        clash=adm.clash.index_put(at, torch.where(demote, 0, adm.clash[who])[None]),
    )
