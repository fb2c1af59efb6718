"""Physics invariants and task rules of the batched world, for both ticks: the Python tick
(the reference) and the fused C++ tick (`sim.fused`, skipped where it cannot be built)."""

import sys

import pytest
import torch
from worldkit import build, package, random_world, robot

from swarmcode_torch.sim import bt
from swarmcode_torch.sim.contacts import collide
from swarmcode_torch.sim.hardware import phenotype
from swarmcode_torch.sim.layout import make_layouts
from swarmcode_torch.sim.rollout import episode_metrics, rollout
from swarmcode_torch.sim.runtime import CompiledStep
from swarmcode_torch.sim.scenario import builtin_names, load_scenario
from swarmcode_torch.sim.state import (
    DELIVERED,
    GROUND,
    Robots,
    WorldParams,
    compatible,
    random_keys,
    reset,
)
from swarmcode_torch.sim.step import step


@pytest.fixture(autouse=True, params=["reference", "fused"])
def tick(request, monkeypatch):
    """Every test once with each tick: `rollout`'s default tick and this module's `step`."""
    if request.param == "fused":
        import swarmcode_torch.sim.rollout as rollout_module
        from swarmcode_torch.sim.fused import FusedTicks

        fused = FusedTicks()
        if not fused.ready(warn=False):
            pytest.skip("the fused C++ tick cannot be built here")
        monkeypatch.setattr(rollout_module, "step", fused)
        monkeypatch.setattr(sys.modules[__name__], "step", fused)
    return request.param


def run(layout, rob, tables, params, ticks, each=None):
    """The state after `ticks` ticks; `each(state)` after every tick (not after the reset)."""

    def observe(t, s):
        if t > 0:
            each(s)

    return rollout(
        layout, rob, tables, params, ticks, return_state=True, observe=observe if each else None
    )[1]


# ------------------------------------------------------------------ physics invariants
@pytest.mark.parametrize("name", ["one-niche", "four-niche"])
def test_no_overlap_and_inside_arena_every_tick(name):
    s, layout, rob, tables, p = random_world(name, E=2, seed=3)
    N = rob.radius.shape[1]
    worst = {"overlap": 0.0, "outside": 0.0}

    def check(st):
        d = torch.cdist(st.pos, st.pos) + torch.eye(N) * 1e3
        overlap = (rob.radius[:, :, None] + rob.radius[:, None, :] - d).clamp_min(0)
        worst["overlap"] = max(worst["overlap"], overlap.max().item())
        r = rob.radius[..., None]
        outside = torch.maximum(r - st.pos, st.pos - (p.arena - r)).clamp_min(0)
        worst["outside"] = max(worst["outside"], outside.max().item())

    run(layout, rob, tables, p, 200, check)
    assert worst["overlap"] < 0.05  # metres, after the contact solver's relaxation passes
    assert worst["outside"] < 1e-5


def test_head_on_elastic_collision_conserves_momentum_and_energy():
    pos = torch.tensor([[[0.0, 0.0], [0.55, 0.0]]])
    vel = torch.tensor([[[1.0, 0.0], [-0.5, 0.0]]])
    radius = torch.tensor([[0.3, 0.3]])
    mass = torch.tensor([[2.0, 5.0]])
    p = WorldParams(arena=100.0)
    empty = torch.zeros(1, 0, 2), torch.zeros(1, 0), torch.zeros(1, 0, dtype=torch.bool)
    pos1, vel1 = collide(pos + 50, vel, radius, mass, torch.ones(1, 2, dtype=torch.bool), *empty, p)
    mom0, mom1 = (mass[..., None] * vel).sum(1), (mass[..., None] * vel1).sum(1)
    ke0, ke1 = (mass * (vel**2).sum(-1)).sum(), (mass * (vel1**2).sum(-1)).sum()
    assert torch.allclose(mom0, mom1, atol=1e-5)
    assert torch.allclose(ke0, ke1, rtol=1e-5)
    # 1-D elastic collision formula
    v1 = ((2 - 5) * 1.0 + 2 * 5 * -0.5) / 7
    v2 = ((5 - 2) * -0.5 + 2 * 2 * 1.0) / 7
    assert torch.allclose(vel1[0, :, 0], torch.tensor([v1, v2]), atol=1e-5)
    assert (pos1[0, 1, 0] - pos1[0, 0, 0]).item() == pytest.approx(0.6, abs=1e-5)


def test_head_on_collision_through_the_tick_conserves_momentum():
    # two robots with empty batteries coast into each other on a frictionless floor
    layout, rob, tables, p = build(
        [robot((3.0, 5.0)), robot((7.0, 5.0), radius=0.4)],
        [package((9.0, 9.0))],
        drag=0.0,
        base_radius=0.5,
    )
    s = reset(layout, rob, p)
    s = s._replace(vel=torch.tensor([[[0.6, 0.0], [-0.3, 0.0]]]), energy=torch.zeros(1, 2))
    compat, keys = compatible(layout, rob, p), random_keys(layout, 2)
    mom0 = (rob.mass[..., None] * s.vel).sum(1)
    for _ in range(100):
        s = step(s, layout, rob, compat, keys, tables, p)
    mom1 = (rob.mass[..., None] * s.vel).sum(1)
    assert s.vel[0, 0, 0] < s.vel[0, 1, 0]  # they bounced: now separating
    assert torch.allclose(mom0, mom1, atol=1e-4)


@pytest.mark.parametrize("name", ["budget", "two-niche"])
def test_long_random_rollout_stays_finite(name):
    s, layout, rob, tables, p = random_world(name, E=3, seed=7)

    def check(st):
        for t in (st.pos, st.vel, st.energy, st.p_pos, st.p_vel):
            assert torch.isfinite(t).all()
        assert (st.energy >= 0).all()

    run(layout, rob, tables, p, 600, check)


# ------------------------------------------------------------------ task rules
def _picked_after(robots, packages, ticks=20, **kw):
    layout, rob, tables, p = build(robots, packages, **kw)
    s = run(layout, rob, tables, p, ticks)
    return s


def test_right_effector_lifts_wrong_effector_does_not():
    pk = package((8.0, 5.0), grips=(1,))
    s = _picked_after([robot((7.5, 5.0), effector=1)], [pk])
    assert s.p_picked.all() and s.holding[0, 0] == 0
    s = _picked_after([robot((7.5, 5.0), effector=0)], [pk])
    assert not s.p_picked.any() and s.holding[0, 0] == -1
    assert torch.equal(s.p_pos, torch.tensor([[[8.0, 5.0]]]))


def test_too_heavy_cannot_lift():
    weak = robot((7.5, 5.0), tiers=(0, 0, 0), torque=0.3, radius=0.3)
    s = _picked_after([weak], [package((8.0, 5.0), mass=2.0)])
    assert s.p_picked.all()
    s = _picked_after([weak], [package((8.0, 5.0), mass=60.0)])
    assert not s.p_picked.any()


def test_too_small_chassis_cannot_lift():
    pk = package((8.0, 5.0), band=(0.35, 0.5))
    assert not _picked_after([robot((7.5, 5.0), radius=0.2)], [pk]).p_picked.any()
    assert _picked_after([robot((7.5, 5.0), radius=0.4)], [pk]).p_picked.all()


def test_collab_package_moves_only_with_all_grips_held():
    pk = package((7.0, 5.0), mass=10.0, grips=(1, 0))
    strong = dict(tiers=(2, 2, 2), torque=1.0, radius=0.25)
    # one pincher alone takes its grip but the package stays where it is
    layout, rob, tables, p = build([robot((8.0, 5.0), effector=1, **strong)], [pk])
    s = run(layout, rob, tables, p, 80)
    assert s.holding[0, 0] == 0 and not s.p_picked.any()
    assert torch.allclose(s.p_pos, torch.tensor([[[7.0, 5.0]]]))
    # with a suction partner at the other grip the package travels to the base and is delivered
    layout, rob, tables, p = build(
        [robot((8.0, 5.0), effector=1, **strong), robot((6.0, 5.5), effector=0, **strong)], [pk]
    )
    s = run(layout, rob, tables, p, 250)
    assert s.p_picked.all()
    m = episode_metrics(s, layout, rob, p)
    assert m["delivered_collab"].item() == 1 and m["grips_delivered"].item() == 2
    assert m["delivered_individual"].item() == 0


def test_a_package_is_delivered_once():
    layout, rob, tables, p = build(
        [robot((5.8, 5.0)), robot((4.0, 5.0))],
        [package((6.5, 5.0)), package((9.0, 9.0), grips=(0,))],
    )
    delivered_at = []

    def each(st):
        delivered_at.append(int((st.p_status == DELIVERED).sum()))

    s = run(layout, rob, tables, p, 300, each)
    m = episode_metrics(s, layout, rob, p)
    assert m["delivered_individual"].item() == 1  # the suction package is never taken
    assert s.p_status[0, 1] == GROUND
    first = delivered_at.index(1)
    assert all(x == 1 for x in delivered_at[first:])  # stays delivered, counted once
    assert (s.holding == -1).all()


def test_empty_battery_stops_a_robot():
    layout, rob, tables, p = build([robot((2.0, 2.0), battery=0.0)], [package((8.5, 8.5))])
    rob = rob._replace(capacity=torch.tensor([[30.0]]))  # a few seconds of driving
    positions, energy = [], []

    def each(st):
        positions.append(st.pos.clone())
        energy.append(st.energy.item())

    run(layout, rob, tables, p, 150, each)
    dead = energy.index(0.0)
    assert 0 < dead < 120
    moved_before = (positions[dead] - positions[0]).norm()
    assert moved_before > 0.2
    # without power the robot coasts to a stop and never moves again
    assert (positions[-1] - positions[dead + 30]).norm() < 1e-6
    # coasting from at most v_cap under drag covers at most v_cap / drag
    assert (positions[-1] - positions[dead]).norm() <= p.v_cap / p.drag + 1e-3


# ------------------------------------------------------------------ whole episodes
def test_same_seed_same_result():
    outs = []
    for _ in range(2):
        s, layout, rob, tables, p = random_world("budget", E=2, seed=11)
        outs.append(rollout(layout, rob, tables, p, 60, return_state=True))
    (m1, s1), (m2, s2) = outs
    for a, b in zip(s1, s2):
        assert torch.equal(a, b)
    for k in m1:
        assert torch.equal(m1[k], m2[k])


@pytest.mark.parametrize("name", builtin_names())
def test_every_scenario_resets_and_runs(name):
    s, layout, rob, tables, p = random_world(name, E=2, seed=1)
    m, st = rollout(layout, rob, tables, p, 5, return_state=True)
    E, N = 2, s.num_robots
    assert st.pos.shape == (E, N, 2) and st.p_pos.shape == (E, s.num_packages, 2)
    assert st.t.item() == 5
    for v in m.values():
        assert v.shape == (E,) and torch.isfinite(v).all()


def test_forage_template_delivers_packages():
    s = load_scenario("two-niche")
    E, N = 4, s.num_robots
    g = torch.Generator().manual_seed(5)
    layout = make_layouts(s, E, g)
    full = lambda v: torch.full((E, N), v)  # noqa: E731
    ph = phenotype(
        full(0.3),
        full(1),
        full(1),
        full(2),
        full(0.8),
        full(0.7),
        (torch.arange(N) % 2).expand(E, N),
    )
    tables = bt.build_tables(bt.template_tensor("forage", 32)[None])
    rob = Robots.from_phenotype(
        ph, torch.ones(E, N, dtype=torch.bool), torch.zeros(E, N, dtype=torch.long)
    )
    m = rollout(layout, rob, tables, WorldParams.for_scenario(s), s.episode_ticks)
    assert (m["delivered_individual"] >= 4).all()
    assert (m["picked_individual"] >= m["delivered_individual"]).all()
    assert (m["energy_used"] > 0).all()


def test_compiled_step_falls_back_to_eager_when_compiling_fails(monkeypatch, tick):
    if tick == "fused":
        pytest.skip("compares the compiled Python tick's fallback with the Python tick")

    def broken_compile(fn, **kw):
        def compiled(*args):
            raise RuntimeError(
                "InvalidCxxCompiler: No working C++ compiler found\n\n"
                "Set TORCHDYNAMO_VERBOSE=1 for the internal stack trace"
            )

        return compiled

    monkeypatch.setattr(torch, "compile", broken_compile)
    fn = CompiledStep()
    s, layout, rob, tables, p = random_world("one-niche", E=1)
    with pytest.warns(RuntimeWarning, match="torch.compile failed .*No working C\\+\\+ compiler"):
        m1 = rollout(layout, rob, tables, p, 5, step_fn=fn)
    m2 = rollout(layout, rob, tables, p, 5)
    assert fn.fn is step and isinstance(fn.error, RuntimeError)
    for k in m1:
        assert torch.equal(m1[k], m2[k])


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the error without CUDA")
def test_cuda_graph_ticks_need_cuda():
    from swarmcode_torch.sim.runtime import CudaGraphTicks

    with pytest.raises(RuntimeError, match="CUDA graphs need a CUDA device"):
        CudaGraphTicks()


def test_waypoints_are_the_counter_hash_of_seed_robot_axis_and_tick():
    # the per-robot keys are precomputed outside the tick; the numbers must stay the hash's
    from swarmcode_torch.sim.state import _waypoints, hash_uniform, waypoint_keys

    seed = torch.tensor([0, 7, 2**40, -(2**35)])
    params = WorldParams(arena=30.0)
    keys = waypoint_keys(seed, 9)
    i = torch.arange(9)
    for t in (0, 1, 99, 2**33):
        tt = torch.tensor(t)
        ref = torch.stack([hash_uniform(seed[:, None], 2 * i + a, tt) for a in (0, 1)], -1)
        assert torch.equal(_waypoints(keys, tt, params), 0.5 + (params.arena - 1.0) * ref)


def test_observe_leaf_changes_nothing_and_sees_what_the_trees_read():
    s, layout, rob, tables, p = random_world("two-niche", E=2, seed=3)
    m0, s0 = rollout(layout, rob, tables, p, 40, return_state=True)
    seen = []
    m1, s1 = rollout(
        layout,
        rob,
        tables,
        p,
        40,
        return_state=True,
        observe_leaf=lambda t, leaf: seen.append((t, leaf.clone())),
    )
    for a, b in zip(s0, s1):
        assert torch.equal(a, b)
    for k in m0:
        assert torch.equal(m0[k], m1[k])
    assert [t for t, _ in seen] == list(range(1, 41))
    assert all(leaf.shape == (2, s.num_robots, bt.NUM_OPCODES) for _, leaf in seen)
    # both observers at once: the state seen before tick t is the one the leaves came from
    states = {}
    rollout(
        layout,
        rob,
        tables,
        p,
        3,
        observe=lambda t, st: states.setdefault(t, st),
        observe_leaf=lambda t, leaf: states.setdefault(-t, leaf),
    )
    assert sorted(states) == [-3, -2, -1, 0, 1, 2, 3]
    assert torch.equal(states[-1], seen[0][1])
