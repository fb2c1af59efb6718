from dataclasses import fields, replace

import pytest
import torch
from genomekit import random_genomes

from swarmcode_torch.coevo.population import R_MAX, R_MIN, Population
from swarmcode_torch.coevo.reproduction import (
    ReproductionParams,
    crossover,
    mutate,
    mutate_bt,
    offspring_quotas,
    random_subtrees,
    replace_subtree,
    reproduce,
    subtree_end,
)
from swarmcode_torch.coevo.selection import elite_count
from swarmcode_torch.coevo.speciation import speciate
from swarmcode_torch.sim.bt import (
    ACT_DROP,
    ACT_MOVE_TO_BASE,
    ACT_MOVE_TO_PACK,
    ACT_MOVE_TO_RANDOM_PACK,
    ACT_PICK_UP,
    ACT_RANDOM_WALK,
    COND_HAS_PACKAGE,
    END,
    LEAF_OPS,
    NOP,
    SEL,
    SEQ,
)


def genome_equal(a: Population, b: Population) -> bool:
    return all(torch.equal(getattr(a, f.name), getattr(b, f.name)) for f in fields(Population))


def check_bounds(g: Population):
    assert g.bt.dtype == torch.long and int(g.bt.min()) >= 0 and int(g.bt.max()) <= 13
    assert torch.all((g.radius >= R_MIN) & (g.radius <= R_MAX))
    for name in ("selectivity", "dominance", "torque_point", "battery_point"):
        x = getattr(g, name)
        assert torch.all((x >= 0) & (x <= 1)), name
    for name in ("chassis", "battery", "motor"):
        x = getattr(g, name)
        assert torch.all((x >= 0) & (x <= 2)), name
    assert torch.all((g.effector == 0) | (g.effector == 1))
    assert g.tag.dtype == torch.bool


@pytest.mark.parametrize(
    "size,count", [(0, 1), (1, 1), (4, 1), (5, 2), (9, 2), (10, 3), (14, 3), (15, 3), (100, 3)]
)
def test_elite_count_table(size, count):
    assert elite_count(size, 3) == count
    assert elite_count(torch.tensor([size]), 3).item() == count


def test_elite_count_max_elite():
    assert elite_count(torch.tensor([1, 20, 100]), 5).tolist() == [1, 5, 5]
    assert elite_count(100, 1) == 1


def test_quotas_proportional_and_exact():
    assert offspring_quotas(torch.tensor([1.0, 1.0, 2.0]), 8).tolist() == [2, 2, 4]
    assert offspring_quotas(torch.tensor([1.0, 1.0, 1.0]), 10).tolist() == [4, 3, 3]
    assert offspring_quotas(torch.tensor([0.0, 0.0]), 5).tolist() == [3, 2]
    assert offspring_quotas(torch.tensor([3.0, 0.0]), 5).tolist() == [5, 0]
    # largest remainder: shares 1.4, 2.8, 5.6, 0.2 -> floors 1, 2, 5, 0 + remainders .8, .6
    assert offspring_quotas(torch.tensor([1.0, 2.0, 4.0, 1 / 7]), 10).tolist() == [1, 3, 6, 0]


def test_quotas_protect():
    assert offspring_quotas(torch.tensor([100.0, 1e-6]), 10).tolist() == [10, 0]
    assert offspring_quotas(torch.tensor([100.0, 1e-6]), 10, protect=1).tolist() == [9, 1]
    assert offspring_quotas(torch.tensor([100.0, 1e-6]), 10, protect=0).tolist() == [10, 0]


def test_quotas_min_share_drops_species_worth_less_than_one_individual():
    f = torch.tensor([10.0, 5.0, 0.6, 0.5, 0.3])  # shares 12.4, 6.2, .74, .62, .37
    assert offspring_quotas(f, 20).tolist() == [12, 6, 1, 1, 0]
    # the three below one individual get nothing; 20 split 10 : 5 -> 13.3, 6.7
    assert offspring_quotas(f, 20, min_share=1.0).tolist() == [13, 7, 0, 0, 0]
    assert offspring_quotas(f, 20, protect=4, min_share=1.0).tolist() == [12, 7, 0, 0, 1]
    # no species reaches the threshold: plain largest remainder, then the protected one gets 1
    assert offspring_quotas(torch.ones(5), 4, min_share=1.0).tolist() == [1, 1, 1, 1, 0]
    assert offspring_quotas(torch.ones(5), 4, protect=4, min_share=1.0).tolist() == [0, 1, 1, 1, 1]
    # shares of exactly 1 are kept despite rounding (1/49 * 49 < 1 in floating point)
    assert offspring_quotas(torch.ones(49), 49, min_share=1.0).tolist() == [1] * 49


@pytest.mark.parametrize("seed", range(20))
def test_quotas_sum_random(seed):
    gen = torch.Generator().manual_seed(seed)
    k = int(torch.randint(1, 30, (1,), generator=gen))
    f = torch.rand(k, generator=gen) * 100
    p = int(torch.randint(1, 500, (1,), generator=gen))
    q = offspring_quotas(f, p)
    assert q.sum().item() == p and torch.all(q >= 0)
    share = f.double() / f.double().sum() * p
    assert torch.all((q.double() - share).abs() < 1.0)


PROG = [
    SEQ,
    COND_HAS_PACKAGE,
    SEL,
    ACT_MOVE_TO_PACK,
    ACT_MOVE_TO_BASE,
    END,
    ACT_RANDOM_WALK,
    END,
    NOP,
    NOP,
]


def test_subtree_end_hand_program():
    bt = torch.tensor([PROG] * 6)
    start = torch.tensor([0, 2, 1, 5, 8, 6])
    assert subtree_end(bt, start).tolist() == [8, 6, 2, 6, 9, 7]
    unclosed = torch.tensor([[SEQ, ACT_PICK_UP, SEL, ACT_DROP, END, NOP]])
    assert subtree_end(unclosed, torch.tensor([0])).tolist() == [6]
    assert subtree_end(unclosed, torch.tensor([2])).tolist() == [5]


def test_replace_subtree_hand_program():
    bt = torch.tensor([PROG] * 3)
    start = torch.tensor([2, 1, 0])
    sub = torch.tensor(
        [
            [ACT_DROP, NOP, NOP, NOP, NOP],
            [SEL, ACT_PICK_UP, ACT_DROP, ACT_MOVE_TO_RANDOM_PACK, END],
            [ACT_RANDOM_WALK, NOP, NOP, NOP, NOP],
        ]
    )
    length = torch.tensor([1, 5, 1])
    out = replace_subtree(bt, start, sub, length)
    assert out.tolist() == [
        [SEQ, COND_HAS_PACKAGE, ACT_DROP, ACT_RANDOM_WALK, END, NOP, NOP, NOP, NOP, NOP],
        [
            SEQ,
            SEL,
            ACT_PICK_UP,
            ACT_DROP,
            ACT_MOVE_TO_RANDOM_PACK,
            END,  # inserted
            SEL,
            ACT_MOVE_TO_PACK,
            ACT_MOVE_TO_BASE,
            END,
        ],  # truncated tail
        [ACT_RANDOM_WALK] + [NOP] * 9,
    ]
    assert torch.equal(bt, torch.tensor([PROG] * 3))  # input untouched


def test_random_subtrees_forms():
    gen = torch.Generator().manual_seed(0)
    sub, length = random_subtrees(2000, ReproductionParams(), gen)
    assert sub.shape == (2000, 5)
    leaves = torch.tensor(LEAF_OPS)
    for row, n in zip(sub.tolist()[:300], length.tolist()[:300]):
        if n == 1:
            assert row[0] in LEAF_OPS and row[1:] == [NOP] * 4
        else:
            assert 3 <= n <= 5 and row[0] in (SEQ, SEL) and row[n - 1] == END
            assert all(x in LEAF_OPS for x in row[1 : n - 1]) and row[n:] == [NOP] * (5 - n)
    assert abs((length == 1).float().mean().item() - 0.5) < 0.05
    assert torch.isin(sub[length == 1, 0], leaves).all()


def test_mutate_bt_point_and_rate():
    gen = torch.Generator().manual_seed(0)
    bt = torch.randint(0, 14, (500, 12), generator=gen)
    p = ReproductionParams(bt_subtree_prob=0.0, bt_mutation_rate=1.0)
    out = mutate_bt(bt, p, gen)
    assert ((out != bt).sum(1) <= 1).all() and (out != bt).any(1).float().mean() > 0.8
    half = mutate_bt(bt, replace(p, bt_mutation_rate=0.5), gen)
    assert abs((half != bt).any(1).float().mean().item() - 0.5 * 13 / 14) < 0.07
    assert torch.equal(mutate_bt(bt, ReproductionParams(bt_mutation_rate=0.0), gen), bt)
    sub = mutate_bt(bt, ReproductionParams(bt_subtree_prob=1.0), gen)
    assert sub.shape == bt.shape and int(sub.min()) >= 0 and int(sub.max()) <= 13


def test_point_mutations_land_on_tree_nodes_not_on_padding():
    gen = torch.Generator().manual_seed(1)
    n, l = 3000, 16
    bt = torch.randint(0, 12, (n, l), generator=gen)  # live opcodes (no NOP) ...
    live = torch.randint(1, l + 1, (n, 1), generator=gen)
    bt = torch.where(torch.arange(l)[None, :] < live, bt, NOP)  # ... then NOP padding
    bt[0] = NOP  # an empty program
    p = ReproductionParams(
        bt_subtree_prob=0.0, bt_mutation_rate=1.0, point_opcode_weights=(1.0,) * 13 + (0.0,)
    )
    out = mutate_bt(bt, p, gen)
    changed = out != bt
    assert (changed.sum(1) <= 1).all()
    # padding never changes; only slot 0 of the empty program can
    pad = bt == NOP
    assert not (changed & pad)[1:].any()
    assert changed[1:].any(1).float().mean() > 0.85  # a redraw may give the same opcode
    # the slot is uniform over the nodes: in 1-node programs it is always slot 0, and over
    # programs of 16 nodes every slot is hit about equally
    full = (live[:, 0] == l) & changed.any(1)
    hits = changed[full].float().sum(0)
    assert hits.min() > 0 and hits.max() < 3 * hits.mean()


def test_gene_mutation_probability_steps_that_share_of_genes():
    gen = torch.Generator().manual_seed(0)
    g = random_genomes(4000, gen, l_tag=16)
    g.radius[:] = 0.3
    g.torque_point[:] = 0.5
    m = mutate(g, ReproductionParams(p_gene_mutation=0.25), gen)
    for name in ("radius", "torque_point"):
        moved = (getattr(m, name) != getattr(g, name)).float().mean().item()
        assert abs(moved - 0.25) < 0.03, name
    assert torch.equal(
        mutate(
            g,
            ReproductionParams(
                p_gene_mutation=0.0, bt_mutation_rate=0.0, p_categorical=0.0, p_tag_flip=0.0
            ),
            gen,
        ).radius,
        g.radius,
    )


def test_crossover_groups_and_one_point_bt():
    gen = torch.Generator().manual_seed(0)
    n = 400
    a = random_genomes(n, gen)
    b = random_genomes(n, gen)
    c = crossover(a, b, gen)
    for name in ("selectivity", "dominance", "radius", "chassis", "effector"):
        x = getattr(c, name)
        assert torch.all((x == getattr(a, name)) | (x == getattr(b, name)))
    # tier and operating point of battery / motor come from the same parent
    from_a = c.battery_point == a.battery_point
    assert torch.equal(c.battery[from_a], a.battery[from_a])
    assert torch.equal(c.battery[~from_a], b.battery[~from_a])
    assert 0.35 < from_a.float().mean() < 0.65
    from_a = c.torque_point == a.torque_point
    assert torch.equal(c.motor[from_a], a.motor[from_a])
    assert torch.all((c.tag == a.tag) | (c.tag == b.tag))
    # BT: a prefix of a followed by the suffix of b at one cut in 1..L-1
    t = torch.arange(12)
    ok = torch.zeros(n, dtype=torch.bool)
    for cut in range(1, 12):
        ok |= (torch.where(t < cut, a.bt, b.bt) == c.bt).all(1)
    assert ok.all()
    # identical parents -> identical child
    assert genome_equal(crossover(a, a, gen), a)


def test_mutate_bounds_and_flip_rate():
    gen = torch.Generator().manual_seed(0)
    g = random_genomes(2000, gen, l_tag=16)
    g.radius[:1000] = R_MAX
    g.selectivity[:1000] = 1.0
    g.dominance[1000:] = 0.0
    params = ReproductionParams(
        p_categorical=0.3, hw_sigma=0.1, p_gene_mutation=1.0, p_tag_flip=None
    )  # None: flip each bit w.p. 1 / L_tag
    m = mutate(g, params, gen)
    check_bounds(m)
    flip = (m.tag != g.tag).float().mean().item()
    assert abs(flip - 1 / 16) < 0.01
    changed = (m.chassis != g.chassis).float().mean().item()
    assert abs(changed - 0.3 * 2 / 3) < 0.03  # resampled w.p. 0.3, new value 2/3
    step = (m.torque_point - g.torque_point)[(g.torque_point > 0.4) & (g.torque_point < 0.6)]
    assert abs(step.std().item() - 0.1) < 0.02


def test_p_effector_sets_the_effector_rate_alone_and_unset_changes_nothing():
    gen = torch.Generator().manual_seed(0)
    g = random_genomes(20000, gen, l_tag=16)
    base = ReproductionParams(p_categorical=0.3, p_effector=None)  # unset: p_categorical
    state = gen.get_state()
    m = mutate(g, replace(base, p_effector=0.05), gen)
    flipped = (m.effector != g.effector).float().mean().item()
    assert abs(flipped - 0.05 / 2) < 0.005  # resampled w.p. 0.05, new value 1/2
    assert abs((m.chassis != g.chassis).float().mean().item() - 0.3 * 2 / 3) < 0.02
    gen.set_state(state)
    same = mutate(g, replace(base, p_effector=0.3), gen)  # the categorical rate, set twice
    gen.set_state(state)
    unset = mutate(g, base, gen)
    assert genome_equal(same, unset)


def test_default_mutation_seldom_founds_a_species():
    # docs/MODEL.md: one mutation alone crosses delta for well under 1 % of offspring
    from swarmcode_torch.coevo.speciation import distance

    gen = torch.Generator().manual_seed(0)
    g = random_genomes(4000, gen, l_tag=16)
    params = ReproductionParams()
    d = distance(g, mutate(g, params, gen)).diagonal()
    assert (d > params.delta).float().mean().item() < 0.01
    # each gene mutates with its own probability: most offspring change, some are exact copies
    assert 0.75 < (d > 0).float().mean().item() < 0.95


def population(seed, p=60):
    gen = torch.Generator().manual_seed(seed)
    g = random_genomes(p, gen)
    r = speciate(g, torch.full((p,), -1), None, torch.zeros(0, dtype=torch.long), 0, delta=1.1)
    fit = torch.rand(p, generator=gen) * 100
    return g, fit, r


def test_reproduce_invariants_and_elites():
    g, fit, r = population(0)
    assert 2 <= r.proto_ids.numel() <= 40
    gen = torch.Generator().manual_seed(1)
    ch, hint, is_elite, parent = reproduce(
        g,
        fit,
        r.species,
        r.proto_index,
        r.proto_ids,
        ReproductionParams(bt_mutation_rate=1.0, p_gene_mutation=1.0),
        gen,
    )
    p = g.size
    assert ch.size == p and hint.shape == (p,) and is_elite.shape == (p,) and parent.shape == (p,)
    check_bounds(ch)
    # elites are exact copies and keep their species id
    assert is_elite.any()
    assert genome_equal(ch.index(is_elite), g.index(parent[is_elite]))
    assert torch.equal(hint, r.species[parent])
    assert parent[is_elite].unique().numel() == int(is_elite.sum())
    # the global best survives
    assert int(fit.argmax()) in parent[is_elite].tolist()
    # every elite is among the top elite_count of its species
    for row in parent[is_elite].tolist():
        members = (r.species == r.species[row]).nonzero().squeeze(1)
        n = elite_count(members.numel(), 3)
        top = members[fit[members].argsort(descending=True)[:n]].tolist()
        assert row in top
    # offspring are mutated (BT mutation rate 1.0 -> nearly all differ from their parent)
    off = ~is_elite
    differs = (ch.bt[off] != g.bt[parent[off]]).any(1) | (ch.radius[off] != g.radius[parent[off]])
    assert differs.all()


@pytest.mark.parametrize(
    "exponent,min_share,quotas",
    [
        (0.0, 0.0, [6, 6, 5]),
        (None, 0.0, [12, 4, 1]),  # the mean, the total (the paper's)
        (None, 1.0, [13, 4, 0]),  # species 9's share .98 < 1: its slot goes to species 7
        # between the total and the mean: 12.4 / sqrt 12, 4 / 2, 1 -> shares 9.25, 5.17, 2.58
        (0.5, 0.0, [9, 5, 3]),
    ],
)
def test_reproduce_elite_counts_and_quotas(exponent, min_share, quotas):
    gen = torch.Generator().manual_seed(0)
    g = random_genomes(17, gen)
    species = torch.tensor([7] * 12 + [3] * 4 + [9])
    fit = torch.ones(17)  # quotas 6, 6, 5
    fit[[2, 5, 8]] = torch.tensor([1.5, 1.4, 1.3])
    fit[[0, 1, 3]] = torch.tensor([0.8, 0.7, 0.7])
    # means 1.033, 1, 1 -> shares 5.79, 5.6, 5.6; sums 12.4, 4, 1 -> shares 12.11, 3.91, 0.98
    ch, hint, is_elite, parent = reproduce(
        g,
        fit,
        species,
        torch.tensor([0, 12, 16]),
        torch.tensor([7, 3, 9]),
        ReproductionParams(quota_size_exponent=exponent, min_share=min_share),
        gen,
    )
    elites = [2, 5, 8, 12, 16] if quotas[2] else [2, 5, 8, 12]  # 3 + 1 (+ 1), best first
    assert parent[is_elite].tolist() == elites
    assert torch.bincount(hint, minlength=10)[[7, 3, 9]].tolist() == quotas


@pytest.mark.parametrize(
    "exponent,total,quotas",
    [
        (1.0, True, [12, 4, 1]),
        (0.0, False, [6, 6, 5]),
        (0.5, False, [9, 5, 3]),
        (0.75, False, [11, 4, 2]),  # 12.4 / 12 ** .25, 4 / 4 ** .25, 1 -> shares 10.8, 4.6, 1.6
    ],
)
def test_quota_size_exponent_spans_the_mean_and_the_total(exponent, total, quotas):
    species = torch.tensor([7] * 12 + [3] * 4 + [9])
    fit = torch.ones(17)
    fit[[2, 5, 8]] = torch.tensor([1.5, 1.4, 1.3])
    fit[[0, 1, 3]] = torch.tensor([0.8, 0.7, 0.7])

    def hint(**kw):
        gen = torch.Generator().manual_seed(0)
        g = random_genomes(17, gen)
        return reproduce(
            g,
            fit,
            species,
            torch.tensor([0, 12, 16]),
            torch.tensor([7, 3, 9]),
            ReproductionParams(min_share=0.0, **kw),
            gen,
        )[1]

    h = hint(quota_size_exponent=exponent)
    assert torch.bincount(h, minlength=10)[[7, 3, 9]].tolist() == quotas
    if total:  # exponent 1 is the total, the quotas of an unset exponent
        assert torch.equal(h, hint(quota_size_exponent=None))


def test_reproduce_zero_quota_species_goes_extinct():
    gen = torch.Generator().manual_seed(0)
    g = random_genomes(16, gen)
    species = torch.tensor([0] * 15 + [1])
    fit = torch.ones(16)
    fit[15] = 1000.0
    ch, hint, is_elite, parent = reproduce(
        g, fit, species, torch.tensor([0, 15]), torch.tensor([0, 1]), ReproductionParams(), gen
    )
    assert ch.size == 16 and torch.all(hint == 1)
    assert parent[is_elite].tolist() == [15] and torch.all(parent == 15)


def test_reproduce_large_tournament_picks_species_best():
    gen = torch.Generator().manual_seed(0)
    g = random_genomes(20, gen)
    species = torch.tensor([0] * 10 + [1] * 10)
    fit = torch.arange(20, dtype=torch.float)
    params = ReproductionParams(tournament_size=200)
    _, hint, is_elite, parent = reproduce(
        g, fit, species, torch.tensor([0, 10]), torch.tensor([0, 1]), params, gen
    )
    assert set(parent[~is_elite].tolist()) <= {9, 19}


def test_reproduce_deterministic():
    g, fit, r = population(3)
    args = (g, fit, r.species, r.proto_index, r.proto_ids, ReproductionParams())
    a = reproduce(*args, torch.Generator().manual_seed(7))
    b = reproduce(*args, torch.Generator().manual_seed(7))
    c = reproduce(*args, torch.Generator().manual_seed(8))
    assert genome_equal(a[0], b[0])
    assert all(torch.equal(x, y) for x, y in zip(a[1:], b[1:]))
    assert not genome_equal(a[0], c[0])


def test_reproduce_rejects_unknown_species():
    g, fit, r = population(0, p=10)
    with pytest.raises(ValueError):
        reproduce(
            g,
            fit,
            torch.full((10,), 999),
            r.proto_index,
            r.proto_ids,
            ReproductionParams(),
            torch.Generator().manual_seed(0),
        )
