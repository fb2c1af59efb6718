import pytest
import torch
from genomekit import random_genomes as _random_genomes

from swarmcode_torch.coevo import speciation
from swarmcode_torch.coevo.population import R_MAX, R_MIN, Population
from swarmcode_torch.coevo.speciation import DistanceWeights, distance, hamming, speciate
from swarmcode_torch.sim.bt import ACT_DROP, ACT_PICK_UP, NOP, SEQ


def make(n, l_tag=8, l_bt=6, **kw):
    """n identical default genomes, with fields overridden by kw (tensors or lists)."""
    g = dict(
        tag=torch.zeros(n, l_tag, dtype=torch.bool),
        selectivity=torch.full((n,), 0.5),
        dominance=torch.full((n,), 0.5),
        bt=torch.full((n, l_bt), NOP, dtype=torch.long),
        radius=torch.full((n,), R_MIN),
        chassis=torch.zeros(n, dtype=torch.long),
        battery=torch.zeros(n, dtype=torch.long),
        motor=torch.zeros(n, dtype=torch.long),
        torque_point=torch.zeros(n),
        battery_point=torch.zeros(n),
        effector=torch.zeros(n, dtype=torch.long),
    )
    for k, v in kw.items():
        g[k] = torch.as_tensor(v, dtype=g[k].dtype)
    return Population(**g)


def random_genomes(n, gen, l_tag=8, l_bt=6):
    """Shorter trees than genomekit's default, so BT distances are coarse."""
    return _random_genomes(n, gen, l_tag, l_bt)


ONLY = dict(w_tag=0.0, w_hw=0.0, w_bt=0.0, w_tool=0.0, w_size=0.0)


def pair():
    a = make(1)
    tag = torch.zeros(1, 8, dtype=torch.bool)
    tag[0, [1, 5]] = True  # H = 2, L = 8
    bt = torch.full((1, 6), NOP)
    bt[0, :3] = torch.tensor([SEQ, ACT_PICK_UP, ACT_DROP])  # 3 of 6 slots differ
    b = make(
        1,
        tag=tag,
        bt=bt,
        chassis=[2],
        torque_point=[0.5],
        effector=[1],
        radius=[R_MIN + 0.4 * (R_MAX - R_MIN)],
    )
    return a, b


@pytest.mark.parametrize(
    "term,expected",
    [("w_tag", 0.0625), ("w_hw", 0.5 / 2**0.5), ("w_bt", 0.5), ("w_tool", 1.0), ("w_size", 0.4)],
)
def test_distance_each_term(term, expected):
    a, b = pair()
    w = DistanceWeights(**{**ONLY, term: 1.0})
    assert distance(a, b, w).item() == pytest.approx(expected, abs=1e-6)
    assert distance(b, a, w).item() == pytest.approx(expected, abs=1e-6)


def test_d_hw_is_over_the_continuous_genes():
    a, b = pair()  # torque point 0 vs 0.5, chassis tier 1 vs 3
    hw_only = {**ONLY, "w_hw": 1.0}
    # the paper: the two continuous operating points only, sqrt(0.5^2) / sqrt(2)
    assert distance(a, b, DistanceWeights(**hw_only)).item() == pytest.approx(0.5 / 2**0.5)
    # a tier change alone is not a hardware distance
    c = make(1, chassis=[2], battery=[1], motor=[2])
    assert distance(a, c, DistanceWeights(**hw_only)).item() == 0.0


def test_distance_gamma_and_weighted_sum():
    a, b = pair()
    assert distance(
        a, b, DistanceWeights(**{**ONLY, "w_tag": 1.0}, gamma=1.0)
    ).item() == pytest.approx(0.25)
    total = 1.0 * 0.0625 + 0.5 * 0.5 / 2**0.5 + 0.3 * 0.5 + 0.35 * 1.0 + 0.7 * 0.4
    assert distance(a, b).item() == pytest.approx(total, abs=1e-6)


def test_distance_pairwise_shape_and_properties():
    gen = torch.Generator().manual_seed(1)
    x, y = random_genomes(7, gen), random_genomes(4, gen)
    d = distance(x, y)
    assert d.shape == (7, 4)
    dd = distance(x, x)
    assert torch.allclose(dd, dd.T) and torch.all(dd.diagonal().abs() < 1e-6)
    # pairwise entries equal the one-by-one computation
    for i in range(7):
        for j in range(4):
            assert d[i, j].item() == pytest.approx(
                distance(x.index(slice(i, i + 1)), y.index(slice(j, j + 1))).item(), abs=1e-6
            )


def test_hamming_exact():
    a = torch.tensor([[0, 0, 0, 0], [1, 1, 1, 1]], dtype=torch.bool)
    b = torch.tensor([[1, 0, 1, 0]], dtype=torch.bool)
    assert torch.equal(hamming(a, b), torch.tensor([[2.0], [2.0]]))
    assert torch.equal(hamming(a, a), torch.tensor([[0.0, 4.0], [4.0, 0.0]]))


def no_prev():
    return dict(prev_proto=None, prev_proto_ids=torch.zeros(0, dtype=torch.long))


def clusters():
    """Rows: A B A C B C A; A/B differ by all tag bits, C by tool and size; tiny noise inside."""
    kind = ["A", "B", "A", "C", "B", "C", "A"]
    n = len(kind)
    tag = torch.zeros(n, 8, dtype=torch.bool)
    eff = torch.zeros(n, dtype=torch.long)
    rad = torch.full((n,), R_MIN)
    bt = torch.full((n, 6), NOP)
    for i, k in enumerate(kind):
        if k == "B":
            tag[i] = True
        if k == "C":
            eff[i], rad[i] = 1, R_MAX
        bt[i, i % 6] = ACT_PICK_UP  # D within a cluster <= 2 * 0.3 / 6
    return make(n, tag=tag, effector=eff, radius=rad, bt=bt)


def test_speciate_clusters():
    g = clusters()
    r = speciate(g, torch.full((7,), -1), **no_prev(), next_species_id=0)
    assert r.species.tolist() == [0, 1, 0, 2, 1, 2, 0]
    assert r.proto_ids.tolist() == [0, 1, 2]
    assert r.proto_index.tolist() == [0, 1, 3]
    assert r.next_species_id == 3


def line(xs):
    """Genomes on a line: with size-only weights 1.0, D = |x_i - x_j|."""
    return make(len(xs), radius=[R_MIN + (R_MAX - R_MIN) * x for x in xs])


SIZE_ONLY = DistanceWeights(**{**ONLY, "w_size": 1.0})


def test_speciate_sequential_founding():
    # row 1 (0.38) joins founder 0 although later founder row 2 (0.75) is closer to it;
    # row 3 (0.40) sees both founders and joins the closer later one.
    g = line([0.0, 0.38, 0.75, 0.40])
    r = speciate(g, torch.full((4,), -1), **no_prev(), next_species_id=0, w=SIZE_ONLY)
    assert r.species.tolist() == [0, 0, 1, 1]
    assert r.proto_index.tolist() == [0, 2]
    # index order matters
    g = line([0.75, 0.38, 0.0])
    r = speciate(g, torch.full((3,), -1), **no_prev(), next_species_id=4, w=SIZE_ONLY)
    assert r.species.tolist() == [4, 4, 5]
    assert r.next_species_id == 6


def test_speciate_carry_over_and_extinction():
    prev = line([0.0, 0.9])  # old prototypes of 5 and 7
    g = line([0.5, 0.3, 0.1, 0.35, 0.2])
    hint = torch.tensor([-1, 5, 9, 5, -1])  # nobody carries 7; 9 unknown
    r = speciate(g, hint, prev, torch.tensor([5, 7]), next_species_id=10, w=SIZE_ONLY)
    # species 5: members by hint rows 1 (0.3) and 3 (0.35) -> row 1 is closest to 0.0
    assert r.proto_ids.tolist()[0] == 5 and r.proto_index.tolist()[0] == 1
    assert 7 not in r.proto_ids.tolist()
    # row 0 (0.5): D to proto 0.3 = 0.2 -> joins 5; row 2 (0.1) joins 5 (0.2), row 4 joins 5
    assert r.species.tolist() == [5, 5, 5, 5, 5]
    assert r.next_species_id == 10
    # now with a far individual: new ids continue from next_species_id
    g = line([0.95, 0.3, 0.1, 0.35, 0.2])
    r = speciate(g, hint, prev, torch.tensor([5, 7]), next_species_id=10, w=SIZE_ONLY)
    assert r.species.tolist() == [10, 5, 5, 5, 5]
    assert r.proto_ids.tolist() == [5, 10] and r.proto_index.tolist() == [1, 0]
    assert r.next_species_id == 11


def test_speciate_carried_members_reassigned():
    # the hint only picks the prototype: hinted members are re-assigned like everyone else
    prev = line([0.0])
    g = line([0.05, 0.6, 0.3])
    hint = torch.tensor([3, 3, -1])
    r = speciate(g, hint, prev, torch.tensor([3]), next_species_id=4, w=SIZE_ONLY)
    # row 1 (0.6) is 0.55 from prototype row 0 -> founds 4 despite its hint; row 2 (0.3) joins 3
    assert r.species.tolist() == [3, 4, 3]
    assert r.proto_ids.tolist() == [3, 4] and r.proto_index.tolist() == [0, 1]


def reference_speciate(g, hint, prev, prev_ids, next_id, delta, w):
    """Straightforward sequential NEAT speciation (Python loop) used as the oracle."""
    p = g.size
    protos: list[tuple[int, int]] = []  # (id, row)
    if prev is not None:
        dprev = distance(g, prev, w)
        for k, sid in enumerate(prev_ids.tolist()):
            members = [i for i in range(p) if hint[i].item() == sid]
            if members:
                best = min(members, key=lambda i: (dprev[i, k].item(), i))
                protos.append((sid, best))
    full = distance(g, g, w)
    species = [None] * p
    for sid, row in protos:
        species[row] = sid
    for i in range(p):
        if species[i] is not None:
            continue
        if protos:
            ds = [full[i, row].item() for _, row in protos]
            j = min(range(len(ds)), key=lambda j: (ds[j], j))
            if ds[j] <= delta:
                species[i] = protos[j][0]
                continue
        protos.append((next_id, i))
        species[i] = next_id
        next_id += 1
    return species, [s for s, _ in protos], [r for _, r in protos], next_id


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("delta", [0.4, 0.8, 1.2])
@pytest.mark.parametrize("rounds", [False, True], ids=["full-matrix", "rounds"])
def test_speciate_matches_sequential_reference(seed, delta, rounds, monkeypatch):
    """Both ways: the [P, P] matrix and founders found on the host, and (a population too large
    for the matrix) the founders in rounds of [P, 1] columns."""
    if rounds:
        monkeypatch.setattr(speciation, "_FULL_MATRIX_MAX", 0)
    gen = torch.Generator().manual_seed(seed)
    g = random_genomes(40, gen)
    prev = random_genomes(5, gen)
    prev_ids = torch.tensor([2, 4, 6, 8, 9])
    hint = torch.tensor([2, 4, 6, 8, -1])[torch.randint(0, 5, (40,), generator=gen)]
    w = DistanceWeights()
    r = speciate(g, hint, prev, prev_ids, next_species_id=20, delta=delta, w=w)
    sp, ids, rows, nxt = reference_speciate(g, hint, prev, prev_ids, 20, delta, w)
    assert r.species.tolist() == sp
    assert r.proto_ids.tolist() == ids
    assert r.proto_index.tolist() == rows
    assert r.next_species_id == nxt
    # prototypes are members of their own species
    assert torch.equal(r.species[r.proto_index], r.proto_ids)


def test_speciate_empty_population():
    g = make(0)
    r = speciate(g, torch.zeros(0, dtype=torch.long), None, torch.zeros(0, dtype=torch.long), 3)
    assert r.species.numel() == 0 and r.proto_ids.numel() == 0 and r.next_species_id == 3


def test_design_distance_is_d_without_the_tag_and_tree_terms():
    from swarmcode_torch.coevo.speciation import design_distance, distance_terms

    g = _random_genomes(6, torch.Generator().manual_seed(3))
    t = distance_terms(g, g)
    d = design_distance(g)
    assert torch.allclose(d, t["hw"] + t["tool"] + t["size"])
    flipped = g.index(torch.arange(6))
    flipped.tag[:] = ~flipped.tag  # another tag, another tree: same designs
    flipped.bt[:] = flipped.bt.roll(1, 0)
    assert torch.equal(design_distance(flipped), d)
    assert (d.diagonal() == 0).all() and torch.equal(d, d.T)
