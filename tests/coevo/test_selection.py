"""The ranking-within-groups helpers against plain Python references, on random inputs with ties."""

import pytest
import torch

from swarmcode_torch.coevo.selection import rank_within_groups, top_per_group, top_table


def reference(group, fitness, first=None):
    """Rows sorted by (group, first desc, fitness desc, row) and each one's rank in its group."""
    first = [False] * len(group) if first is None else first
    order = sorted(range(len(group)), key=lambda i: (group[i], not first[i], -fitness[i], i))
    rank, seen = [], {}
    for i in order:
        rank.append(seen.get(group[i], 0))
        seen[group[i]] = rank[-1] + 1
    return order, rank


def random_shape(gen):
    """(P, K): up to 39 rows in 1..5 groups."""
    return (
        int(torch.randint(0, 40, (1,), generator=gen)),
        int(torch.randint(1, 6, (1,), generator=gen)),
    )


def random_case(gen, p, k):
    group = torch.randint(0, k, (p,), generator=gen)
    fitness = torch.randint(0, 4, (p,), generator=gen).float()  # few values: many ties
    fitness[torch.rand(p, generator=gen) < 0.2] = -torch.inf
    first = torch.rand(p, generator=gen) < 0.5
    n = torch.randint(0, 4, (k,), generator=gen)
    return group, fitness, first, n


@pytest.mark.parametrize("seed", range(20))
def test_rank_within_groups_matches_reference(seed):
    gen = torch.Generator().manual_seed(seed)
    p, k = random_shape(gen)
    group, fitness, first, _ = random_case(gen, p, k)
    for use_first in (False, True):
        f = first if use_first else None
        want = reference(group.tolist(), fitness.tolist(), first.tolist() if use_first else None)
        for sizes in (None, torch.bincount(group, minlength=k + 2)):
            order, rank = rank_within_groups(group, fitness, sizes, first=f)
            assert (order.tolist(), rank.tolist()) == want


@pytest.mark.parametrize("seed", range(20))
def test_top_per_group_and_table_match_reference(seed):
    gen = torch.Generator().manual_seed(100 + seed)
    p, k = random_shape(gen)
    group, fitness, first, n = random_case(gen, p, k)
    order, rank = rank_within_groups(group, fitness)
    ref, _ = reference(group.tolist(), fitness.tolist())
    best = [[i for i in ref if group[i] == g][: int(n[g])] for g in range(k)]
    assert top_per_group(order, rank, group, n).tolist() == [i for rows in best for i in rows]

    # rows of group k (no group) never enter the table
    none = group.clone()
    none[torch.rand(p, generator=gen) < 0.3] = k
    order, rank = rank_within_groups(none, fitness, first=first)
    ref, _ = reference(none.tolist(), fitness.tolist(), first.tolist())
    m = int(n.max())
    table = top_table(order, rank, none, n)
    assert table.shape == (k, m)
    for g in range(k):
        rows = [i for i in ref if none[i] == g][: int(n[g])]
        assert table[g].tolist() == rows + [-1] * (m - len(rows))


def test_empty_population():
    group, fitness = torch.zeros(0, dtype=torch.long), torch.zeros(0)
    order, rank = rank_within_groups(group, fitness, torch.zeros(3, dtype=torch.long))
    assert order.numel() == rank.numel() == 0
    assert top_per_group(order, rank, group, torch.ones(3, dtype=torch.long)).numel() == 0
    assert top_table(order, rank, group, torch.ones(3, dtype=torch.long)).tolist() == [[-1]] * 3
