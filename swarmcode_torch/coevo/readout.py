"""What a generation reports, read on the host in one transfer (`read_generation`).

Each read of a device value on the host waits for the device; a generation makes this one
(besides speciation's, `speciation.speciate`): the best team, the species' sizes, the summary
numbers and the genes the records keep, and the number of elites that reproduction keeps
(which sizes its offspring). Everything is gathered on the device in fixed shapes, copied in
one transfer, and taken apart on the host: the population's genes and phenotype whole (the
best team's rows are picked there, with no gather on the device).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import torch
from torch import Tensor

from ..sim.hardware import Phenotype
from ..sim.tensors import cast
from .evaluation import EvalResult
from .population import Population

_NUMPY = {
    torch.bool: np.bool_,
    torch.uint8: np.uint8,
    torch.int8: np.int8,
    torch.int16: np.int16,
    torch.int32: np.int32,
    torch.int64: np.int64,
    torch.float16: np.float16,
    torch.float32: np.float32,
    torch.float64: np.float64,
}


@dataclass(frozen=True, eq=False)
class BestTeam:
    """This generation's best team, the focal team of the individual with the highest (gated)
    fitness, on the host: each of its distinct population rows (sorted) with what the
    generation computed of it. The application builds its report record from this
    (`app.records.team_record`)."""

    rows: Tensor  # [R] population rows of the team's robots
    genome: Population  # [R] their genes
    phenotype: Phenotype  # [R] their phenotype (of the generation's one computation)
    species: Tensor  # [R] their species
    count: Tensor  # [R] robots of each row in the team
    baseline_count: Tensor  # [R] of each row in the baseline team it was scored against
    focal: Tensor  # [R] bool: the focal individual's row
    metrics: dict  # the team's metrics (means over trials), floats
    fitness: float  # the team's score (ungated)
    cost: float  # the team's cost


@dataclass(frozen=True, eq=False)
class Readout:
    """What `read_generation` read, on the host (but `team_rows`)."""

    best_team: BestTeam
    team_rows: Tensor  # [S] population rows of the best team's robots (-1: empty slot), device
    population: dict[int, int]  # members of each species, by id (ascending)
    team: dict[str, int]  # the best team's robots of each species, most first (the first of
    #                       equals: the lower row)
    fit_max: float  # highest smoothed fitness in the population
    fit_mean: float
    focal_max: float  # highest focal team score (ungated)
    radius: Tensor  # [P] genes of the evaluated population
    dominance: Tensor  # [P]
    selectivity: Tensor  # [P]
    n_elites: int  # elites that reproduction keeps


def best_index(res: EvalResult, tie: float = 0.0) -> Tensor:
    """[1] the evaluation whose focal team is the generation's best team: the highest fitness
    score, gated (a focal whose marginal contribution is not positive is penalised, so a strong
    team carried by its partners is not credited to a focal that weakens it); with `tie` > 0
    (`best_team_tie`), of the focal teams within that fraction of the highest, one with the
    fewest species, the highest of those. No host read."""
    fit = res.fitness
    if tie <= 0:
        return fit.argmax().view(1)
    top = fit.max()
    near = fit >= top - tie * top.abs()
    count = res.swarms.focal_species_count
    fewest = torch.where(near, count, count.max() + 1).min()
    return torch.where(near & (count == fewest), fit, -torch.inf).argmax().view(1)


def read_generation(
    genome: Population,
    species: Tensor,
    res: EvalResult,
    phenotype: Phenotype,
    fitness: Tensor,
    n_elites: Tensor,
    tie: float = 0.0,
) -> Readout:
    """The generation's report, in one transfer: the best team (`best_index`'s, at `tie`), the
    species' sizes, the summary numbers of `fitness` (the smoothed fitness) and `res`, three
    genes of every individual, and `n_elites` (0-d). The best team's genes and phenotype are
    its rows of the population's, all of which are read."""
    b = best_index(res, tie)
    team = res.swarms.focal_team.index_select(0, b)[0]
    names = [f.name for f in fields(Population)]
    n_g, n_ph = len(names), len(Phenotype._fields)
    # every gene and phenotype value of the population (the team's rows are picked on the host),
    # the team's scores and metrics at b
    scores = [res.focal, res.team_cost, *(cast(v, torch.float) for v in res.team_metrics.values())]
    h = to_host(
        [getattr(genome, n) for n in names]
        + list(phenotype)
        + [
            b,
            team,
            res.swarms.baseline_team.index_select(0, b),
            species,
            torch.stack(scores).index_select(1, b),
            torch.stack([res.focal.max(), fitness.max(), fitness.mean()]),
            n_elites,
        ]
    )
    genes, ph = h[:n_g], h[n_g : n_g + n_ph]
    (b_h, team_h, base_h, species_h, at_b, stats, n_el) = h[n_g + n_ph :]
    focal, cost, metrics = at_b[0, 0], at_b[1, 0], at_b[2:, 0]
    valid = team_h >= 0
    rows, counts = np.unique(team_h[valid], return_counts=True)
    ids, sizes = np.unique(species_h, return_counts=True)

    def t(a: np.ndarray) -> Tensor:
        return torch.from_numpy(np.ascontiguousarray(a))

    best_team = BestTeam(
        rows=t(rows),
        genome=Population(**{n: t(x[rows]) for n, x in zip(names, genes)}),
        phenotype=Phenotype(*(t(x[rows]) for x in ph)),
        species=t(species_h[rows]),
        count=t(counts.astype(np.int64)),
        baseline_count=t((base_h.reshape(1, -1) == rows[:, None]).sum(1, dtype=np.int64)),
        focal=t(rows == b_h[0]),
        metrics=dict(zip(res.team_metrics, metrics.tolist())),
        fitness=float(focal),
        cost=float(cost),
    )
    return Readout(
        best_team=best_team,
        team_rows=team,
        population={int(i): int(n) for i, n in zip(ids.tolist(), sizes.tolist())},
        team={
            str(s): n
            for s, n in sorted(
                zip(species_h[rows].tolist(), counts.tolist()), key=lambda sc: -sc[1]
            )
        },
        fit_max=float(stats[1]),
        fit_mean=float(stats[2]),
        focal_max=float(stats[0]),
        radius=t(genes[names.index("radius")]),
        dominance=t(genes[names.index("dominance")]),
        selectivity=t(genes[names.index("selectivity")]),
        n_elites=int(n_el),
    )


def to_host(tensors: list[Tensor]) -> list[np.ndarray]:
    """Host (numpy) copies of tensors of one device, in one transfer: the values of each dtype
    concatenated, their bytes concatenated (the widest dtype first, so that every part stays
    aligned), copied, and split (bit for bit the tensors, their dtypes and shapes)."""
    groups: dict[torch.dtype, list[int]] = {}
    for i, x in enumerate(tensors):
        groups.setdefault(x.dtype, []).append(i)
    order = sorted(groups, key=lambda d: -d.itemsize)

    def flat(i: int) -> Tensor:
        return tensors[i] if tensors[i].dim() == 1 else tensors[i].reshape(-1)

    parts = [
        flat(ix[0]) if len(ix) == 1 else torch.cat([flat(i) for i in ix])
        for ix in (groups[d] for d in order)
    ]
    data = cast(torch.cat([f.view(torch.uint8) for f in parts]), device="cpu").numpy()
    out: list[np.ndarray] = [np.empty(0)] * len(tensors)
    pos = 0
    for d in order:
        for i in groups[d]:
            x = tensors[i]
            n = x.numel() * d.itemsize
            out[i] = data[pos : pos + n].view(_NUMPY[d]).reshape(x.shape)
            pos += n
    return out
