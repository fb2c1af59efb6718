import torch

from swarmcode_torch.coevo.partners import assemble_swarms, choose_partners, elite_rows
from swarmcode_torch.coevo.selection import elite_count


def tags_at_distance(ds, l=16):
    """[len(ds), l] bool tags with the first d bits set (Hamming distance d from all-zero)."""
    t = torch.zeros(len(ds), l, dtype=torch.bool)
    for i, d in enumerate(ds):
        t[i, :d] = True
    return t


def test_choose_partners_selectivity_threshold():
    # focal tag = zeros; prototypes at H/L = 3/16, 4/16 (== selectivity), 5/16, and 0 (own species)
    proto_tag = tags_at_distance([3, 4, 5, 0])
    proto_ids = torch.tensor([10, 11, 12, 13])
    elites = torch.tensor([[100, -1], [101, -1], [102, -1], [103, -1]])
    tag = torch.zeros(2, 16, dtype=torch.bool)
    sel = torch.tensor([0.25, 0.3125001])
    species = torch.tensor([13, 10])
    gen = torch.Generator().manual_seed(0)
    out = choose_partners(tag, sel, species, proto_ids, proto_tag, elites, gen)
    assert out.tolist() == [
        [100, -1, -1, -1],  # 3/16 < 0.25; 4/16 not (strict)
        [-1, 101, 102, 103],
    ]  # own species 10 never a partner


def test_choose_partners_zero_selectivity_and_no_elites():
    proto_tag = tags_at_distance([0, 0])
    gen = torch.Generator().manual_seed(0)
    out = choose_partners(
        torch.zeros(2, 16, dtype=torch.bool),
        torch.tensor([0.0, 1.0]),
        torch.tensor([5, 5]),
        torch.tensor([6, 7]),
        proto_tag,
        torch.tensor([[-1, -1], [4, -1]]),
        gen,
    )
    assert out.tolist() == [[-1, -1], [-1, 4]]  # species 6 has no elite


def test_choose_partners_uniform_elite_and_padding():
    n = 6000
    tag = torch.zeros(n, 16, dtype=torch.bool)
    elites = torch.tensor([[-1, 7, -1, 9, 8]])  # padding anywhere is ignored
    gen = torch.Generator().manual_seed(3)
    out = choose_partners(
        tag,
        torch.ones(n),
        torch.zeros(n, dtype=torch.long),
        torch.tensor([1]),
        tags_at_distance([2]),
        elites,
        gen,
    )[:, 0]
    counts = torch.bincount(out, minlength=10)[7:10].float() / n
    assert set(out.tolist()) == {7, 8, 9}
    assert torch.allclose(counts, torch.full((3,), 1 / 3), atol=0.03)


def test_choose_partners_deterministic():
    gen1, gen2 = torch.Generator().manual_seed(5), torch.Generator().manual_seed(5)
    args = (
        torch.zeros(50, 16, dtype=torch.bool),
        torch.ones(50),
        torch.zeros(50, dtype=torch.long),
        torch.tensor([0, 1, 2]),
        tags_at_distance([1, 2, 3]),
        torch.tensor([[0, 1, 2], [3, 4, -1], [5, -1, -1]]),
    )
    assert torch.equal(choose_partners(*args, gen1), choose_partners(*args, gen2))


def test_elite_rows_counts_and_order():
    # species 4: 6 members -> N = 2; species 9: 1 member -> 1; species 2: 11 members -> 3
    species = torch.tensor([4] * 6 + [9] + [2] * 11)
    fitness = torch.arange(18, dtype=torch.float)
    fitness[2] = 100.0  # best of species 4
    has = torch.ones(18, dtype=torch.bool)
    has[17] = False  # best-looking member of 2 has no fitness
    out = elite_rows(fitness, has, species, torch.tensor([4, 9, 2]), lambda s: elite_count(s, 3))
    assert out.tolist() == [[2, 5, -1], [6, -1, -1], [16, 15, 14]]


def test_elite_rows_ties_missing_fitness_and_empty_species():
    species = torch.tensor([1, 1, 1, 3])
    fitness = torch.tensor([5.0, 5.0, float("nan"), 1.0])
    has = torch.tensor([True, True, False, True])
    out = elite_rows(
        fitness, has, species, torch.tensor([1, 2, 3]), lambda s: torch.full_like(s, 3)
    )
    assert out.tolist() == [[0, 1, 2], [-1, -1, -1], [3, -1, -1]]


def test_elite_rows_rank_unevaluated_members_last():
    # species 4: 6 members (N = 2), 1 evaluated; species 9: a new species of 2 unevaluated
    # members; species 2: 11 members (N = 3), all evaluated
    species = torch.tensor([4] * 6 + [9] * 2 + [2] * 11)
    fitness = torch.arange(19, dtype=torch.float)
    has = torch.ones(19, dtype=torch.bool)
    has[[0, 1, 2, 3, 5, 6, 7]] = False  # species 4 keeps only row 4 evaluated
    ids = torch.tensor([4, 9, 2])
    # unevaluated members fill the elite count after the evaluated ones, lowest row first
    out = elite_rows(fitness, has, species, ids, lambda s: elite_count(s, 3))
    assert out.tolist() == [[4, 0, -1], [6, -1, -1], [18, 17, 16]]


def test_assemble_dominance_frequencies():
    b, s = 4000, 10
    dominance = torch.tensor([0.2, 0.6, 0.2, 0.9])  # row 3 is not in any team
    focal = torch.zeros(b, dtype=torch.long)
    partners = torch.tensor([[1, 2, -1]]).expand(b, 3)
    gen = torch.Generator().manual_seed(0)
    sw = assemble_swarms(focal, partners, dominance, s, gen)
    assert torch.equal(sw.focal_team[:, :3], torch.tensor([[0, 1, 2]]).expand(b, 3))
    clones = sw.focal_team[:, 3:].reshape(-1)
    freq = torch.bincount(clones, minlength=4).float() / clones.numel()
    assert torch.allclose(freq, torch.tensor([0.2, 0.6, 0.2, 0.0]), atol=0.02)
    assert torch.all(sw.focal_species_count == 3) and torch.all(sw.baseline_species_count == 2)
    # baseline: partners only, focal slots re-filled 0.75 / 0.25
    assert not torch.any(sw.baseline_team == 0) and torch.all(sw.baseline_team >= 1)
    refill = sw.baseline_team[sw.focal_slot]
    f1 = (refill == 1).float().mean().item()
    assert abs(f1 - 0.75) < 0.02


def test_assemble_baseline_replaces_exactly_focal_slots():
    gen = torch.Generator().manual_seed(1)
    b, s, k = 500, 6, 4
    # species k's elites are rows 1 + 5k .. 5 + 5k (distinct across species)
    partners = 1 + 5 * torch.arange(k) + torch.randint(0, 5, (b, k), generator=gen)
    partners[torch.rand(b, k, generator=gen) < 0.5] = -1
    focal = torch.zeros(b, dtype=torch.long)
    sw = assemble_swarms(focal, partners, torch.rand(21, generator=gen), s, gen)
    assert torch.equal(sw.focal_slot, sw.focal_team == 0)
    assert torch.all(sw.focal_slot[:, 0])
    same = sw.baseline_team == sw.focal_team
    assert torch.equal(~same, sw.focal_slot)
    has = (partners >= 0).any(1)
    assert torch.all(sw.baseline_team[has] >= 1)
    assert torch.all(sw.baseline_team[~has][sw.focal_slot[~has]] == -1)
    # every team partner gets a slot and nothing else appears
    for i in range(50):
        ps = set(partners[i][partners[i] >= 0].tolist())
        assert set(sw.focal_team[i].tolist()) == ps | {0}
        assert sw.focal_species_count[i].item() == len(ps) + 1
        assert sw.baseline_species_count[i].item() == len(ps)


def test_assemble_more_partners_than_slots():
    b, s = 5000, 3
    partners = torch.tensor([[10, 11, 12, 13, 14]]).expand(b, 5)
    focal = torch.zeros(b, dtype=torch.long)
    gen = torch.Generator().manual_seed(2)
    sw = assemble_swarms(focal, partners, torch.ones(15), s, gen)
    assert torch.all(sw.focal_team[:, 0] == 0)
    assert torch.all(sw.focal_team[:, 1:] >= 10)
    assert torch.all(sw.focal_team[:, 1] != sw.focal_team[:, 2])
    assert torch.all(sw.partner_in_team.sum(1) == 2) and torch.all(sw.focal_species_count == 3)
    freq = sw.partner_in_team.float().mean(0)
    assert torch.allclose(freq, torch.full((5,), 0.4), atol=0.03)


def test_assemble_no_partners_zero_dominance_and_determinism():
    focal = torch.tensor([3, 4])
    partners = torch.tensor([[-1, -1], [5, -1]])
    dominance = torch.zeros(6)
    gen = torch.Generator().manual_seed(0)
    sw = assemble_swarms(focal, partners, dominance, 4, gen)
    assert sw.focal_team[0].tolist() == [3, 3, 3, 3]
    assert sw.baseline_team[0].tolist() == [-1, -1, -1, -1]
    assert sw.focal_species_count.tolist() == [1, 2] and sw.baseline_species_count.tolist() == [
        0,
        1,
    ]
    assert set(sw.focal_team[1].tolist()) <= {4, 5} and sw.focal_team[1, :2].tolist() == [4, 5]
    assert set(sw.baseline_team[1].tolist()) == {5}
    sw2 = assemble_swarms(focal, partners, dominance, 4, torch.Generator().manual_seed(0))
    assert torch.equal(sw.focal_team, sw2.focal_team)
    assert torch.equal(sw.baseline_team, sw2.baseline_team)
    one = assemble_swarms(focal, partners, dominance, 1, torch.Generator().manual_seed(0))
    assert one.focal_team.tolist() == [[3], [4]] and one.baseline_team.tolist() == [[-1], [-1]]


def test_niche_representatives_largest_then_fittest_then_oldest():
    from swarmcode_torch.coevo.partners import niche_representatives

    cap = torch.tensor(
        [[1, 0], [1, 0], [1, 0], [0, 1], [0, 0], [0, 0], [0, 1], [0, 1]], dtype=torch.bool
    )
    sizes = torch.tensor([5, 7, 7, 3, 2, 2, 3, 9])
    best = torch.tensor([9.0, 1.0, 2.0, 1.0, 1.0, 1.0, 1.0, 5.0])
    has = torch.tensor([True] * 7 + [False])
    rep = niche_representatives(cap, sizes, best, has).tolist()
    # niche {0}: species 1 and 2 are the largest, 2 has the fitter elite (0's 9 does not count);
    # niche {1}: 3 and 6 tie in size and fitness, the first (oldest) represents it, and 7, the
    # largest, has no elite, so it neither represents nor displaces; 4 and 5 lift nothing: each
    # represents itself
    assert rep == [False, False, True, True, True, True, False, False]


def test_choose_partners_allowed_mask_removes_species_and_keeps_the_draws():
    args = (
        torch.zeros(40, 16, dtype=torch.bool),
        torch.ones(40),
        torch.zeros(40, dtype=torch.long),
        torch.tensor([0, 1, 2, 3]),
        tags_at_distance([1, 2, 3, 4]),
        torch.tensor([[0, 1, 2], [3, 4, -1], [5, -1, -1], [6, 7, 8]]),
    )
    free = choose_partners(*args, torch.Generator().manual_seed(2))
    allowed = torch.tensor([True, False, True, False])
    masked = choose_partners(*args, torch.Generator().manual_seed(2), allowed)
    assert (masked[:, ~allowed] == -1).all() and (masked[:, 1:2] == -1).all()
    assert torch.equal(masked[:, allowed], free[:, allowed])
    assert (free[:, 1:] >= 0).all()  # without the mask every species is one


def test_one_partner_per_niche_puts_a_duplicate_beside_its_resident():
    from dataclasses import replace

    from swarmcode_torch.coevo.config import EvalConfig
    from swarmcode_torch.coevo.evaluation import plan_evaluation
    from swarmcode_torch.coevo.population import from_designs
    from swarmcode_torch.sim.scenario import load_scenario

    def design(effector, radius):
        return {
            "effector": effector,
            "radius": radius,
            "chassis_tier": 3,
            "battery_tier": 3,
            "motor_tier": 3,
            "torque_point": 1.0,
            "battery_point": 1.0,
            "dominance": 0.5,
            "selectivity": 1.0,
            "count": 1,
            "bt": [13] * 4,
        }

    # species 10: 3 heavy pinchers (the resident), 11: 2 heavy pinchers of another design (a
    # duplicate of its niche), 12: a heavy suction robot, 13: a robot that lifts nothing
    genome, _ = from_designs(
        [design("pincher", 0.4)] * 3
        + [design("pincher", 0.45)] * 2
        + [design("suction", 0.4), design("pincher", 0.31)]
    )
    species = torch.tensor([10, 10, 10, 11, 11, 12, 13])
    ids = torch.tensor([10, 11, 12, 13])
    proto_index = torch.tensor([0, 3, 5, 6])
    fitness, has = torch.ones(7), torch.ones(7, dtype=torch.bool)
    four = load_scenario("four-niche")
    cfg = EvalConfig(swarm_size=6, ticks=10, trials=1, partners_per_niche="all")

    def partner_species(c):
        plan = plan_evaluation(
            genome,
            species,
            ids,
            proto_index,
            fitness,
            has,
            four,
            c,
            torch.Generator().manual_seed(0),
        )
        team = plan.swarms.focal_team
        return [
            sorted({int(species[r]) for r in row if r >= 0} - {int(species[i])})
            for i, row in enumerate(team)
        ]

    everyone = partner_species(cfg)
    one = partner_species(replace(cfg, partners_per_niche="one"))
    assert everyone[0] == [11, 12, 13] and everyone[3] == [10, 12, 13]
    assert one[0] == [12, 13]  # the resident's team leaves the duplicate out
    assert one[3] == [10, 12, 13]  # the duplicate's team holds the resident
    assert one[5] == [10, 13] and one[6] == [10, 12]  # one species of each other niche


def test_nearest_refill_gives_every_focal_slot_to_the_nearest_partner_in_the_team():
    from swarmcode_torch.coevo.partners import assemble_swarms

    partner_rows = torch.tensor([[5, 6, 7], [5, -1, 7]])
    dist = torch.tensor([[0.9, 0.2, 0.5], [0.9, 0.1, 0.5]])  # focal 1 lacks partner 6
    g = torch.Generator().manual_seed(0)
    sw = assemble_swarms(
        torch.tensor([0, 1]), partner_rows, torch.ones(8), 8, g, refill_distance=dist
    )
    assert (sw.baseline_team[0][sw.focal_slot[0]] == 6).all()
    assert (sw.baseline_team[1][sw.focal_slot[1]] == 7).all()
    keep = ~sw.focal_slot
    assert torch.equal(sw.baseline_team[keep], sw.focal_team[keep])
