"""Selection, mating and mutation: per-species elitism, NEAT offspring quotas, tournaments,
crossover and mutation of whole populations as batched tensor operations."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, fields

import torch
from torch import Tensor

from ..sim.bt import END, LEAF_OPS, NOP, NUM_OPCODES, SEL, SEQ, compute_jumps
from ..sim.tensors import arange, cast
from .config import ReproductionParams
from .population import CROSSOVER_GROUPS, GENE_BOUNDS, GENE_VALUES, SOCIAL_GENES, Population
from .selection import elite_count, group_sizes, rank_within_groups, top_per_group
from .speciation import distance

DistanceFn = Callable[[Population, Population], Tensor]


def offspring_quotas(
    adjusted_fitness_sum: Tensor,
    population_size: int | Tensor,
    protect: int | Tensor | None = None,
    min_share: float = 0.0,
) -> Tensor:
    """[K] total adjusted fitness per species -> [K] long quotas summing to population_size.

    Proportional shares rounded by largest remainder (ties: lowest index); all-zero (or negative)
    fitness gives equal shares. A species whose share (population_size * its fraction of the
    total) is below `min_share` gets 0 and the others share its slots (0, or no species reaching
    it: no threshold). `protect` (a species position) is guaranteed a quota >= 1, taken
    from the species with the largest quota (ties: lowest index). In `reproduce`, elites are
    counted inside the quota: a species whose quota is below its elite count keeps only its top
    `quota` elites; a quota of 0 means the species gets no child (it goes extinct) unless protected.
    """
    dev = adjusted_fitness_sum.device
    k = adjusted_fitness_sum.numel()
    if k == 0:
        return torch.zeros(0, dtype=torch.long, device=dev)
    # no value is read on the host here (each would be a device sync): the branches are
    # torch.where over tensors, `protect` may be a 0-d tensor (a position: a mask `is_p`)
    if isinstance(protect, int) and not -k <= protect < k:
        raise IndexError(f"protect {protect} is out of range for {k} species")
    idx = arange(k, dev)
    is_p = (
        None if protect is None else idx == (protect % k if isinstance(protect, int) else protect)
    )
    f = torch.nan_to_num(cast(adjusted_fitness_sum, torch.double), nan=0.0).clamp(min=0.0)
    f = torch.where(f.sum() > 0, f, 1.0)
    if min_share > 0:
        # a relative tolerance, so that an exact share of min_share is not lost to rounding
        keep = f / f.sum() * population_size >= min_share * (1 - 1e-9)
        any_kept = (f * keep).sum() > 0  # else no species qualifies: no threshold
        if is_p is not None:
            keep = keep | is_p
        f = torch.where(any_kept & ~keep, 0.0, f)
    share = f / f.sum() * population_size
    base = share.floor()
    q = base.long()
    rem = (population_size - q.sum()).clamp(0, k)  # +1 to the rem largest remainders
    order = torch.sort(share - base, descending=True, stable=True).indices
    q = q.index_add(0, order, (idx < rem).long())
    if is_p is not None:
        # take 1 from the largest quota (no host read: population_size may be a tensor)
        need = torch.where(is_p, q, 0).sum() == 0
        if isinstance(population_size, Tensor):
            need = need & (population_size > 0)
        elif population_size <= 0:
            need = need & False
        q = q - ((idx == q.argmax()) & need).long()
        q = torch.where(is_p & need, 1, q)
    return q


def floor_quotas(
    quota: Tensor,
    essential: Tensor,
    priority: Tensor,
    floor: int,
    protect: int | Tensor | None = None,
) -> Tensor:
    """quota [K] long, essential [K] bool, priority [K] (lower first) -> [K] long quotas of the
    same total in which up to total // (2 * floor) essential species (lowest priority first)
    get at least `floor`, whatever their share, and every species' slots above its floor are the
    remaining slots shared in proportion to its quota above its floor (largest remainder). A
    floor of 0, or no essential species, leaves the quotas as they are."""
    k = quota.numel()
    if floor <= 0 or k == 0:
        return quota
    dev = quota.device
    total = quota.sum()
    cap = total // (2 * floor)
    key = torch.where(essential, priority.double(), torch.full((k,), torch.inf, device=dev))
    order = torch.sort(key, stable=True).indices
    place = torch.empty_like(order)
    place[order] = torch.arange(k, device=dev)
    chosen = essential & (place < cap)
    base = torch.where(chosen, floor, 0)
    excess = (quota - base).clamp(min=0)
    return base + offspring_quotas(excess.double(), total - base.sum(), protect=protect)


# ---------------------------------------------------------------------------------------------
# Behavior-tree operators


def subtree_end(bt: Tensor, start: Tensor) -> Tensor:
    """[N, L] opcodes, [N] start slot -> [N] end (exclusive) of the subtree rooted at start:
    the jump index (past the matching END for SEQ/SEL, L if unclosed; start + 1 otherwise)."""
    return compute_jumps(bt).gather(1, cast(start, torch.long)[:, None]).squeeze(1)


def replace_subtree(bt: Tensor, start: Tensor, subtree: Tensor, subtree_len: Tensor) -> Tensor:
    """[N, L] opcodes, [N] start, [N, S] new subtrees, [N] their lengths -> [N, L] programs.

    Slots [start, subtree_end) are replaced by subtree[:len]; the tail shifts and the result is
    truncated or NOP-padded to L.
    """
    n, l = bt.shape
    if l == 0 or n == 0:
        return bt.clone()
    s = cast(start, torch.long)[:, None]
    end = compute_jumps(bt).gather(1, s)  # [N, 1] `subtree_end`
    d = arange(l, bt.device) - s  # [N, L] each slot's place after the start
    m = subtree_len[:, None]
    from_sub = subtree.gather(1, d.clamp(0, subtree.shape[1] - 1))
    tail = d + (end - m)  # the slot of the old program that shifts there
    from_tail = torch.where(tail < l, bt.gather(1, tail.clamp(0, l - 1)), NOP)
    return torch.where(d < 0, bt, torch.where(d < m, from_sub, from_tail))


@functools.lru_cache(maxsize=8)
def _leaf_ops(device: torch.device) -> Tensor:
    """[len(LEAF_OPS)] long (built once per device, never written to)."""
    return torch.tensor(LEAF_OPS, dtype=torch.long, device=device)


def random_subtrees(
    n: int,
    params: ReproductionParams,
    generator: torch.Generator,
    device: torch.device | str = "cpu",
) -> tuple[Tensor, Tensor]:
    """-> ([n, max_leaves + 2] long subtrees NOP-padded, [n] long lengths): a leaf, or SEQ/SEL +
    1..max leaves + END."""
    device = torch.device(device)
    ml = params.subtree_max_leaves
    s_max = ml + 2
    is_leaf = torch.rand(n, generator=generator, device=device) < params.subtree_leaf_prob
    ctrl = torch.randint(0, 2, (n,), generator=generator, device=device)  # SEQ=0 / SEL=1
    k = torch.randint(1, ml + 1, (n,), generator=generator, device=device)
    leaves = _leaf_ops(device)[
        torch.randint(0, len(LEAF_OPS), (n, s_max), generator=generator, device=device)
    ]
    # a leaf: its leaf at slot 0; else SEQ / SEL at slot 0, leaves at 1..k and END at k + 1
    head = torch.where(is_leaf, leaves[:, 0], torch.where(ctrl == 0, SEQ, SEL))
    t, kk = arange(s_max, device), k[:, None]
    body = torch.where(t <= kk, leaves, torch.where(t == kk + 1, END, NOP))
    sub = torch.where(t == 0, head[:, None], torch.where(is_leaf[:, None], NOP, body))
    return sub, torch.where(is_leaf, 1, k + 2)


def _random_node(bt: Tensor, generator: torch.Generator) -> Tensor:
    """[N, L] opcodes -> [N, 1] a uniform slot among each row's non-NOP slots (0 if none)."""
    live = bt != NOP
    count = live.sum(1, keepdim=True)
    u = torch.rand(bt.shape[0], 1, generator=generator, device=bt.device)
    k = torch.minimum((u * count).long(), (count - 1).clamp(min=0))  # the k-th node
    # the k-th node is the first slot where the running count of nodes reaches k + 1
    hit = live.cumsum(1) == k + 1
    return hit.to(torch.int32).argmax(1, keepdim=True)


@functools.lru_cache(maxsize=8)
def _opcode_weights(weights: tuple[float, ...], device: torch.device) -> Tensor:
    """The point mutation's opcode weights as a tensor (built once per setting and device)."""
    if len(weights) != NUM_OPCODES:
        raise ValueError(f"point_opcode_weights needs {NUM_OPCODES} entries")
    return torch.tensor(weights, dtype=torch.float, device=device)


def mutate_bt(bt: Tensor, params: ReproductionParams, generator: torch.Generator) -> Tensor:
    """[N, L] opcodes -> [N, L] opcodes after one point (may redraw the same opcode) or
    subtree-replacement event per row, w.p. bt_mutation_rate."""
    n, l = bt.shape
    if n == 0 or l == 0:
        return bt.clone()
    dev = bt.device
    do = torch.rand(n, generator=generator, device=dev) < params.bt_mutation_rate
    sub = torch.rand(n, generator=generator, device=dev) < params.bt_subtree_prob
    weights = _opcode_weights(tuple(params.point_opcode_weights), dev)
    point = bt
    for _ in range(params.bt_point_count):
        slot = _random_node(point, generator)
        op = torch.multinomial(weights, n, replacement=True, generator=generator)
        point = point.scatter(1, slot, cast(op, bt.dtype)[:, None])
    start = torch.randint(0, l, (n,), generator=generator, device=dev)
    subtree, sub_len = random_subtrees(n, params, generator, dev)
    replaced = replace_subtree(bt, start, cast(subtree, bt.dtype), sub_len)
    return torch.where(do[:, None], torch.where(sub[:, None], replaced, point), bt)


# ---------------------------------------------------------------------------------------------
# Whole-genome operators


def crossover(a: Population, b: Population, generator: torch.Generator) -> Population:
    """Parents [N], [N] -> child [N]: uniform per gene group, uniform per tag bit, one-point BT
    crossover at the same cut in 1..L-1 (`mate` of every pair)."""
    n = a.size
    rows = torch.arange(n, device=a.bt.device)
    cross = torch.ones(n, dtype=torch.bool, device=rows.device)
    return mate(Population.cat([a, b]), rows, rows + n, cross, generator)


def mate(
    genome: Population, p1: Tensor, p2: Tensor, do_cross: Tensor, generator: torch.Generator
) -> Population:
    """Rows p1 [N], p2 [N] of `genome`, do_cross [N] bool -> children [N]: where do_cross the
    crossover of the two parents (uniform per gene group, uniform per tag bit, one-point BT
    crossover at the same cut in 1..L-1), else a copy of p1 (the draws are made for every
    child alike). Each gene is read once, from each child's row for it."""
    n = p1.numel()
    dev = genome.bt.device
    keep = ~do_cross[:, None]  # [N, 1] a copy of p1
    pick = torch.rand(n, len(CROSSOVER_GROUPS), generator=generator, device=dev) < 0.5
    group_rows = torch.where(pick | keep, p1[:, None], p2[:, None]).unbind(1)
    out: dict[str, Tensor] = {}
    for rows, group in zip(group_rows, CROSSOVER_GROUPS):
        for name in group:
            out[name] = getattr(genome, name)[rows]
    bits = torch.rand(n, genome.tag.shape[1], generator=generator, device=dev) < 0.5
    out["tag"] = torch.where(bits | keep, genome.tag[p1], genome.tag[p2])
    l = genome.bt.shape[1]
    if l >= 2:
        cut = torch.randint(1, l, (n, 1), generator=generator, device=dev)
        first = (arange(l, dev) < cut) | keep
        out["bt"] = torch.where(first, genome.bt[p1], genome.bt[p2])
    else:
        out["bt"] = genome.bt[p1]
    return Population(**{f.name: out[f.name] for f in fields(Population)})


def _gauss_draws(x: Tensor, generator: torch.Generator, p: float) -> tuple[Tensor, Tensor | None]:
    """The draws of a Gaussian step of x [N]: standard normal noise [N] (x's dtype), and where
    p < 1, uniforms [N] (the entries below p are stepped)."""
    noise = torch.randn(x.shape, generator=generator, device=x.device, dtype=x.dtype)
    u = torch.rand(x.shape, generator=generator, device=x.device) if p < 1.0 else None
    return noise, u


@functools.lru_cache(maxsize=8)
def _gauss_constants(
    names: tuple[str, ...], sigmas: tuple[float, ...], dtype: torch.dtype, device: torch.device
) -> tuple[Tensor, Tensor, Tensor]:
    """[G, 1] lower and upper bounds (GENE_BOUNDS) and noise scales sigma (hi - lo) of the genes
    `names` (built once per setting and device, never written to)."""
    lo, hi = zip(*(GENE_BOUNDS[n] for n in names))
    scale = [s * (h - l) for s, l, h in zip(sigmas, lo, hi)]

    def column(v) -> Tensor:
        return torch.tensor(v, dtype=dtype, device=device)[:, None]

    return column(lo), column(hi), column(scale)


def _gauss_steps(
    genes: dict[str, Tensor],
    draws: dict[str, tuple[Tensor, Tensor | None]],
    params: ReproductionParams,
) -> dict[str, Tensor]:
    """The continuous genes `genes` ([N] each, one dtype) stepped by their `_gauss_draws`: x +
    N(0, (sigma (hi - lo))^2), clipped to GENE_BOUNDS [lo, hi], each entry w.p.
    p_gene_mutation (social_sigma for SOCIAL_GENES, else hw_sigma); all in one pass over
    their stack."""
    names = tuple(draws)
    x = torch.stack([genes[n] for n in names])
    noise = torch.stack([draws[n][0] for n in names])
    if params.p_gene_mutation < 1.0:
        u = torch.stack([u for _, u in draws.values() if u is not None])
        noise = noise * (u < params.p_gene_mutation)
    sigmas = tuple(params.social_sigma if n in SOCIAL_GENES else params.hw_sigma for n in names)
    lo, hi, scale = _gauss_constants(names, sigmas, x.dtype, x.device)
    return dict(zip(names, (x + noise * scale).clamp(lo, hi).unbind()))


def _resample(x: Tensor, n_values: int, p: float, generator: torch.Generator) -> Tensor:
    """[N] long -> [N] long, each entry replaced w.p. p by a uniform value in 0..n_values-1."""
    hit = torch.rand(x.shape, generator=generator, device=x.device) < p
    new = torch.randint(0, n_values, x.shape, generator=generator, device=x.device, dtype=x.dtype)
    return torch.where(hit, new, x)


def mutate(g: Population, params: ReproductionParams, generator: torch.Generator) -> Population:
    """Population [N] -> mutated Population [N] (BT, continuous and categorical hardware, tag
    bits, selectivity, dominance).

    Genes are drawn in field order: tag bits flip w.p. p_tag_flip (None: 1 / L_tag), the BT by
    `mutate_bt`, continuous genes by `_gauss_draws` (stepped together by `_gauss_steps`, in
    their GENE_BOUNDS), categorical ones by `_resample` (w.p. p_categorical; the effector w.p.
    p_effector where that is set).
    """
    l_tag = g.tag.shape[1]
    p_flip = params.p_tag_flip if params.p_tag_flip is not None else (1.0 / l_tag if l_tag else 0.0)
    out = {}
    draws = {}  # the continuous genes' draws
    for name in (f.name for f in fields(Population)):
        x = getattr(g, name)
        if name == "tag":
            out[name] = x ^ (torch.rand(x.shape, generator=generator, device=x.device) < p_flip)
        elif name == "bt":
            out[name] = mutate_bt(x, params, generator)
        elif name in GENE_BOUNDS:
            draws[name] = _gauss_draws(x, generator, params.p_gene_mutation)
        else:
            p_cat = (
                params.p_effector
                if name == "effector" and params.p_effector is not None
                else params.p_categorical
            )
            out[name] = _resample(x, GENE_VALUES[name], p_cat, generator)
    out.update(_gauss_steps({n: getattr(g, n) for n in draws}, draws, params))
    return Population(**{f.name: out[f.name] for f in fields(Population)})


@dataclass(frozen=True, eq=False)
class Quotas:
    """The species' shares of the next generation (`quotas`): pos [P] each individual's species
    position, sizes [K], fit [P] float32, quota [K] long (elites counted in it), n_elite [K] long
    elites kept of each species."""

    pos: Tensor
    sizes: Tensor
    fit: Tensor
    quota: Tensor
    n_elite: Tensor


def quotas(
    fitness: Tensor,
    species: Tensor,
    proto_ids: Tensor,
    params: ReproductionParams,
    essential: Tensor | None = None,
    priority: Tensor | None = None,
    present: bool = False,
) -> Quotas:
    """`reproduce`'s quotas and elite counts (see there). `present`: every individual's species is
    in proto_ids and every species there has a member (as `speciate` gives them), so nothing is
    checked and no value is read on the host; else ValueError for a species not listed, and
    empty species get 0."""
    p = fitness.numel()
    dev = fitness.device
    k = proto_ids.numel()
    ids = cast(proto_ids, torch.long, dev)
    match = species[:, None] == ids
    if p and not present and not bool(match.any(1).all()):
        raise ValueError("every individual's species must be listed in proto_ids")
    pos = match.to(torch.int32).argmax(1)
    sizes = group_sizes(pos, k)
    fit = cast(fitness, torch.float)
    fsum = torch.zeros(k, dtype=torch.float64, device=dev).index_add_(0, pos, fit.double())
    if params.quota_size_exponent is not None:  # mean x size ** exponent
        n = sizes.clamp(min=1).double()
        adjusted = fsum / n * n.pow(params.quota_size_exponent)
    else:  # the paper's total
        adjusted = fsum
    # empty species get 0 (`present`: there are none, every species is a position of its own)
    nonempty = None if present else (sizes > 0).nonzero().squeeze(1)

    def of_nonempty(t: Tensor) -> Tensor:
        return t if nonempty is None else t[nonempty]

    quota = torch.zeros(k, dtype=torch.long, device=dev)
    if p:
        best_pos = pos.take(fit.argmax())  # the species of the global best (0-d, no host read)
        protect = best_pos if nonempty is None else (nonempty == best_pos).int().argmax()
        q = offspring_quotas(of_nonempty(adjusted), p, protect=protect, min_share=params.min_share)
        if essential is not None and params.essential_floor > 0:
            pri = priority if priority is not None else torch.zeros(k, device=dev)
            q = floor_quotas(
                q, of_nonempty(essential), of_nonempty(pri), params.essential_floor, protect=protect
            )
        quota = q if nonempty is None else quota.index_put((nonempty,), q)
    n_elite = torch.minimum(torch.minimum(elite_count(sizes, params.max_elite), quota), sizes)
    return Quotas(pos, sizes, fit, quota, n_elite)


def reproduce(
    genome: Population,
    fitness: Tensor,
    species: Tensor,
    proto_index: Tensor,
    proto_ids: Tensor,
    params: ReproductionParams,
    generator: torch.Generator,
    distance_fn: DistanceFn = distance,
    essential: Tensor | None = None,
    priority: Tensor | None = None,
    plan: Quotas | None = None,
    n_elites: int | None = None,
) -> tuple[Population, Tensor, Tensor, Tensor]:
    """Population [P], fitness [P], species [P], prototypes [K] -> (children [P],
    child_species_hint [P], is_elite [P], parent_index [P]).

    Quotas: proportional to each species' total fitness (`params.quota_size_exponent` None, the
    paper's) or to its mean fitness x its size ** quota_size_exponent, the species of the global
    best protected (>= 1). Elites (top elite_count per species, capped by the quota) are copied
    unchanged and listed first (species by proto order, best first); the remaining quota is filled
    by offspring: p1 by in-species tournament, p2 by in-species tournament within `delta` of p1 (and
    != p1), up to mate_tries tries, else a global tournament (!= p1); crossover w.p. crossover_same
    / crossover_cross (same / different species) else clone p1; then every offspring is mutated.
    `essential` [K] bool (with `priority` [K], lower first): species kept at
    `params.essential_floor` slots at least (`floor_quotas`), exempt from `min_share`.
    Hints: the elite's own species / p1's species; parent_index: the elite row / p1.
    `distance_fn(genome, genome)` is called once ([P, P]). Fitness must be finite for every
    individual. `plan`: the `quotas` already computed (then `essential` and `priority` are not
    read); `n_elites`: their number of elites, `plan.n_elite.sum()`, known on the host (then no
    value is read on the host here).
    """
    p = genome.size
    dev = genome.bt.device
    k = proto_ids.numel()
    if plan is None:
        plan = quotas(fitness, species, proto_ids, params, essential, priority)
    pos, sizes, fit, quota, n_elite = plan.pos, plan.sizes, plan.fit, plan.quota, plan.n_elite

    order, rank = rank_within_groups(pos, fit, sizes)  # by (species, fitness desc, row)
    elite = top_per_group(order, rank, pos, n_elite, n_elites)

    n_off = None if n_elites is None else p - n_elites  # quotas sum to p
    off_pos = torch.repeat_interleave(arange(k, dev), quota - n_elite, output_size=n_off)
    n_off = off_pos.numel()
    p1, p2 = _parents(genome, fit, order, sizes, off_pos, params, generator, distance_fn)

    same = species[p2] == species[p1]
    p_cross = torch.where(same, params.crossover_same, params.crossover_cross)
    do_cross = torch.rand(n_off, generator=generator, device=dev) < p_cross
    child = mutate(mate(genome, p1, p2, do_cross, generator), params, generator)

    children = Population.cat([genome.index(elite), child])
    parent = torch.cat([elite, p1])
    is_elite = arange(parent.numel(), dev) < elite.numel()
    return children, species[parent], is_elite, parent


def _parents(
    genome: Population,
    fit: Tensor,
    order: Tensor,
    sizes: Tensor,
    off_pos: Tensor,
    params: ReproductionParams,
    generator: torch.Generator,
    distance_fn: DistanceFn,
) -> tuple[Tensor, Tensor]:
    """`reproduce`'s parents of each offspring (its species' position `off_pos` [N]; `order`:
    the rows by species and fitness, `sizes` [K]): p1 by in-species tournament, p2 by in-species
    tournament within `delta` of p1 (and != p1), up to mate_tries tries, else a global
    tournament (!= p1) -> (p1 [N], p2 [N])."""
    p = genome.size
    dev = genome.bt.device
    starts = sizes.cumsum(0) - sizes
    n_off = off_pos.numel()
    ts = params.tournament_size

    # each offspring's species: its size, its last rank and its first place in `order`
    size = sizes[off_pos].view(-1, 1, 1)
    last, first = size - 1, starts[off_pos].view(-1, 1, 1)

    def tournament(tries: int) -> Tensor:
        """-> [N, tries] tournament winners (rows) within each offspring's species."""
        u = torch.rand(n_off, tries, ts, generator=generator, device=dev)
        rows = order[first + (u * size).long().clamp(max=last)]
        win = fit[rows].argmax(-1, keepdim=True)
        return rows.gather(-1, win).squeeze(-1)

    p1 = tournament(1)[:, 0]
    cand = tournament(params.mate_tries)  # [N, tries]
    dmat = distance_fn(genome, genome)
    p1_col = p1[:, None]
    ok = (dmat[p1_col, cand] <= params.delta) & (cand != p1_col)
    local_p2 = cand.gather(1, ok.to(torch.int32).argmax(1, keepdim=True)).squeeze(1)
    if p > 1:
        g = torch.randint(0, p - 1, (n_off, ts), generator=generator, device=dev)
        g = g + (g >= p1_col)  # uniform over rows != p1
    else:
        g = torch.zeros(n_off, ts, dtype=torch.long, device=dev)
    global_p2 = g.gather(1, fit[g].argmax(1, keepdim=True)).squeeze(1)
    return p1, torch.where(ok.any(1), local_p2, global_p2)
