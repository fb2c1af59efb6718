"""The Triton tick (`sim.triton_tick`) and the sorted cell list (`sim.cell_list`) against the
Python reference, on the CPU under Triton's interpreter (``TRITON_INTERPRET=1``, set per test
before the kernels are imported; `triton_tick` re-imports them when it changes, so it does not
matter what imported torch or triton first).

Tolerance: from the same state the two ticks give the same integer state (holding, grip, stuck,
statuses, holders, picked, t) and floats within ``rtol = atol = 1e-5`` (measured: relative
3e-6 at most, on velocities; the contact solver sums each robot's pairs in another order, and
`norm` is sqrt(x x + y y) in the kernels). Over many ticks the two drift apart as any two
float orders do in contact dynamics, so, as for the fused C++ tick (test_fused.py), the
reference's trajectory is followed and each compared tick starts from the reference's state.

The interpreter is slow (about 0.1 ms of Python per op and program), so the worlds are tiny
and the N = 1000 tests use the interpreter's large blocks; the CUDA test (-m gpu) runs the
compiled kernels.
"""

import warnings
from dataclasses import replace

import pytest
import torch
from worldkit import random_world

from swarmcode_torch.sim import triton_tick as tt
from swarmcode_torch.sim.cell_list import (
    build_cell_list,
    cell_candidates,
    contact_pairs,
    dense_contact_pairs,
    max_cell_count,
    robot_contacts_cell_list,
)
from swarmcode_torch.sim.contacts import _robot_contacts_dense, cell_overflow, collide
from swarmcode_torch.sim.hardware import R_MAX, R_MIN
from swarmcode_torch.sim.sense import sense
from swarmcode_torch.sim.state import TickInputs, WorldParams, compatible, random_keys, reset
from swarmcode_torch.sim.step import step

needs_triton = pytest.mark.skipif(not tt.has_triton(), reason="triton is not installed")
TOL = dict(rtol=1e-5, atol=1e-5)  # ticks of the scenarios' worlds
# the dense solver's form, x_i + x_i sum_j c_ij - sum_j c_ij x_j, loses digits to cancellation
# where robots overlap several others: two orders of its sums differ by up to 1e-4 there (the
# reference's broad phase against its dense solver: 1e-4 in test_broad_phase.py)
CROWD_TOL = dict(rtol=0.0, atol=1e-4)


@pytest.fixture
def interpret(monkeypatch):
    """Triton's interpreter for this test: the kernels are re-imported under it. triton itself
    is imported first without it, as any other user of triton in this process (torch's
    inductor) sees it: triton decides once, at that import, whether its own library functions
    are interpreted, and the kernels cope with either."""
    import triton.language  # noqa: F401

    monkeypatch.setenv("TRITON_INTERPRET", "1")
    monkeypatch.setattr(tt, "GPU_BLOCKS_IN_INTERPRETER", False)
    return monkeypatch


def _world(name, E, seed, absent=0.0):
    _, layout, rob, tables, p = random_world(name, E=E, seed=seed)
    if absent:
        g = torch.Generator().manual_seed(seed + 1)
        rob = rob._replace(present=torch.rand(rob.radius.shape, generator=g) >= absent)
    inp = TickInputs(
        layout, rob, compatible(layout, rob, p), random_keys(layout, rob.radius.shape[1]), tables
    )
    return inp, p


def _compare(a, b, what):
    for name, x, y in zip(a._fields, a, b):
        if x.dtype.is_floating_point:
            torch.testing.assert_close(y, x, **TOL, msg=lambda m, n=name: f"{what} {n}: {m}")
        else:
            assert torch.equal(x, y), (what, name, (x != y).sum())


def crowd(E, N, arena, seed):
    """Robots packed densely enough that most touch several others; some slots absent (as
    test_broad_phase.py's)."""
    g = torch.Generator().manual_seed(seed)
    pos = torch.rand(E, N, 2, generator=g) * arena
    vel = (torch.rand(E, N, 2, generator=g) - 0.5) * 1.2
    radius = R_MIN + (R_MAX - R_MIN) * torch.rand(E, N, generator=g)
    mass = 2.0 + 10.0 * torch.rand(E, N, generator=g)
    present = torch.rand(E, N, generator=g) > 0.1
    return pos, vel, radius, mass, present


def _obstacles(E, O, arena, seed=5):
    g = torch.Generator().manual_seed(seed)
    o_pos = torch.rand(E, O, 2, generator=g) * arena
    o_r = 0.2 + 0.5 * torch.rand(E, O, generator=g)
    o_p = torch.rand(E, O, generator=g) > 0.25
    return o_pos, o_r, o_p


# ------------------------------------------------------------------ without triton
def test_without_triton_the_module_imports_and_the_python_tick_runs(monkeypatch):
    monkeypatch.setattr(tt, "has_triton", lambda: False)
    monkeypatch.setenv("TRITON_INTERPRET", "1")
    assert not tt.available("cpu") and not tt.available("cuda") and not tt.interpreting()
    inp, p = _world("one-niche", 1, seed=0)
    s = reset(inp.layout, inp.robots, p)
    fn = tt.TritonTicks()
    with pytest.warns(RuntimeWarning, match="Triton tick cannot run: triton is not installed"):
        a = fn(s, *inp, p)
    for x, y in zip(a, step(s, *inp, p)):
        assert torch.equal(x, y)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # said once
        fn(a, *inp, p)


@needs_triton
def test_available_only_under_the_interpreter_on_the_cpu(monkeypatch):
    monkeypatch.delenv("TRITON_INTERPRET", raising=False)
    assert not tt.available("cpu")
    import triton.language as tl
    from triton.runtime.interpreter import InterpretedFunction

    if isinstance(tl.sum, InterpretedFunction):  # this process imported triton interpreted
        with pytest.raises(RuntimeError, match="imported with TRITON_INTERPRET=1"):
            tt._kernels()
    else:
        assert not tt._kernels().INTERPRET  # compiled-mode kernels: importing needs no GPU
    monkeypatch.setenv("TRITON_INTERPRET", "1")
    assert tt.available("cpu") and not tt.available("cuda")
    assert tt._kernels().INTERPRET  # re-imported under the interpreter


@needs_triton
def test_an_interpreted_tick_leaves_triton_as_it_was(interpret):
    # Triton 3.9's interpreter leaves triton.language.core patched after a kernel calls one
    # of its library functions: compiled Triton (inductor's too) would then fail in this
    # process. The tick puts it back.
    import triton.language as tl

    objs = [tl, tl.core, tl.math, tl.standard, tl.core.tensor, tl.core.dtype]
    before = [dict(vars(o)) for o in objs]
    inp, p = _world("one-niche", 1, seed=0)
    tt.step_triton(reset(inp.layout, inp.robots, p), *inp, p)
    for o, b in zip(objs, before):  # (names it adds stay, see _restoring_triton_language)
        now = dict(vars(o))
        assert [k for k in b if now.get(k) is not b[k]] == [], o


def test_step_triton_is_the_reference_code_with_two_phases_replaced():
    assert tt.step_triton.__code__ is step.__code__
    assert tt.step_triton.__globals__["sense"] is tt.sense_triton
    assert tt.step_triton.__globals__["collide"] is tt.collide_triton
    assert step.__globals__["collide"] is collide  # the reference is untouched
    with pytest.raises(RuntimeError, match="no longer reads"):
        tt._rebind(step, "x", not_a_name_of_step=lambda: None)


# ------------------------------------------------------------------ the pair kernels
@needs_triton
@pytest.mark.parametrize("path", ["dense", "cells"])
@pytest.mark.parametrize("gpu_blocks", [False, True])
def test_collide_agrees_with_the_reference(interpret, path, gpu_blocks):
    interpret.setattr(tt, "GPU_BLOCKS_IN_INTERPRETER", gpu_blocks)
    E, N, arena = 3, 70, 6.0  # crowded (2.3 contacts a robot); walls and obstacles are hit
    pos, vel, radius, mass, present = crowd(E=E, N=N, arena=arena, seed=3)
    mass[0, :5] = 1e6  # robots waiting at a grip (anchor_mass)
    obst = _obstacles(E, 5, arena)
    # each path against the reference's solver of the same form: dense, or its broad phase
    p = WorldParams(arena=arena, broad_phase_min_robots=10**9 if path == "dense" else 1)
    assert not cell_overflow(pos, present, p).any()
    tol = CROWD_TOL if path == "dense" else TOL  # measured: 4e-5 and 7e-7
    for iters in (3, 1, 0):  # the default; a single pass; obstacles and walls only
        q = replace(p, collision_iters=iters)
        a = collide(pos, vel, radius, mass, present, *obst, q)
        b = tt.collide_triton(pos, vel, radius, mass, present, *obst, q)
        if iters:  # robot contacts acted
            assert (a[0] - pos).abs().max() > 0.05 and (a[1] - vel).abs().max() > 0.1
        torch.testing.assert_close(b[0], a[0], **tol)
        torch.testing.assert_close(b[1], a[1], **tol)


@needs_triton
@pytest.mark.parametrize("gpu_blocks", [False, True])
def test_sensing_agrees_with_the_reference(interpret, gpu_blocks):
    interpret.setattr(tt, "GPU_BLOCKS_IN_INTERPRETER", gpu_blocks)
    inp, p = _world("budget", 2, seed=3, absent=0.2)  # H = 24: several chunks of grips
    s = reset(inp.layout, inp.robots, p)
    for t in range(41):
        if t % 20 == 0:
            a = sense(s, inp.layout, inp.robots, inp.compat, inp.keys, p)
            b = tt.sense_triton(s, inp.layout, inp.robots, inp.compat, inp.keys, p)
            for name, x, y in zip(a._fields, a, b):
                if x.dtype.is_floating_point:
                    torch.testing.assert_close(y, x, **TOL)
                else:
                    assert torch.equal(x, y), (t, name)
        s = step(s, *inp, p)


# ------------------------------------------------------------------ whole ticks
@needs_triton
@pytest.mark.parametrize(
    "name,E,absent,ticks,every,gpu_blocks",
    [("four-niche", 3, 0.0, 160, 20, False), ("two-niche", 2, 0.3, 80, 10, True)],
)
def test_ticks_agree_with_the_reference_state_by_state(
    interpret, name, E, absent, ticks, every, gpu_blocks
):
    interpret.setattr(tt, "GPU_BLOCKS_IN_INTERPRETER", gpu_blocks)
    inp, p = _world(name, E, seed=4, absent=absent)
    s = reset(inp.layout, inp.robots, p)
    fn = tt.TritonTicks()
    for t in range(ticks):
        a = step(s, *inp, p)
        if t % every == every - 1 or t == 0:
            with warnings.catch_warnings():
                warnings.simplefilter("error")  # no fallback: the kernels ran
                _compare(a, fn(s, *inp, p), f"tick {t + 1}")
        if t == ticks // 2:  # some robots run out of energy
            g = torch.Generator().manual_seed(t)
            a = a._replace(
                energy=torch.where(torch.rand(a.energy.shape, generator=g) < 0.2, 0.0, a.energy)
            )
        s = a
    if name == "four-niche":  # the compared ticks saw pick-ups and deliveries
        assert bool(s.p_picked.any()) and bool((s.p_status == 2).any())


@needs_triton
def test_swarmcode_tick_triton_selects_the_triton_tick_for_a_rollout(interpret):
    """SWARMCODE_TICK=triton: `tick_function` gives the Triton tick (not compiled, named
    "triton"), and a whole rollout with it ends where the reference's does."""
    from swarmcode_torch.sim.rollout import rollout
    from swarmcode_torch.sim.runtime import tick_function, tick_mode

    interpret.setenv("SWARMCODE_TICK", "triton")
    fn, compiled = tick_function(torch.device("cpu"))
    assert isinstance(fn, tt.TritonTicks) and not compiled and tick_mode(fn, compiled) == "triton"
    inp, p = _world("two-niche", 2, seed=6)
    _, ref = rollout(inp.layout, inp.robots, inp.tables, p, 40, step_fn=step, return_state=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the kernels ran: no fallback to the Python tick
        _, got = rollout(inp.layout, inp.robots, inp.tables, p, 40, step_fn=fn, return_state=True)
    # 40 ticks of the two sums' orders drift apart by a few 1e-5 (each tick alone is within
    # TOL: test_ticks_agree_with_the_reference_state_by_state); the discrete state is the same
    for name, x, y in zip(ref._fields, ref, got):
        if x.dtype.is_floating_point:
            torch.testing.assert_close(
                y, x, rtol=1e-3, atol=1e-3, msg=lambda m, n=name: f"{n}: {m}"
            )
        else:
            assert torch.equal(x, y), name
    interpret.setenv("SWARMCODE_TICK", "bogus")
    with pytest.raises(ValueError, match="'fused', 'reference' or 'triton'"):
        tick_function(torch.device("cpu"))


# ------------------------------------------------------------------ the broad phase at N = 1000
def test_cell_list_finds_exactly_the_dense_contact_pairs_at_1000():
    pos, _, radius, _, present = crowd(E=2, N=1000, arena=22.0, seed=7)
    cl = build_cell_list(pos, present, 1.1, 22.0)
    E, N = present.shape
    # the list: each environment's rows once, sorted by cell, cells' runs where start says
    assert torch.equal(cl.order.sort(1).values, torch.arange(N).expand(E, N))
    sorted_cell = cl.cell.gather(1, cl.order)
    assert bool((sorted_cell[:, 1:] >= sorted_cell[:, :-1]).all())
    g2 = cl.grid * cl.grid
    c = torch.arange(g2 + 1)
    assert torch.equal(cl.start[:, :-1], torch.searchsorted(sorted_cell, c.repeat(E, 1)))
    assert max_cell_count(cl) <= 32
    pairs = contact_pairs(cl, pos, radius, present)
    dense = dense_contact_pairs(pos, radius, present)
    assert dense.shape[0] > 2000  # crowded enough
    assert torch.equal(pairs, dense)
    # with a capacity below the fullest cell, pairs are missed: None (exact) is the default
    rows, valid = cell_candidates(cl, present, capacity=2)
    assert valid.sum() < cell_candidates(cl, present)[1].sum()


def test_cell_list_contact_solver_matches_the_dense_one_at_1000():
    pos, vel, radius, mass, present = crowd(E=2, N=1000, arena=22.0, seed=8)
    p = WorldParams(arena=22.0)
    a = _robot_contacts_dense(pos, vel, radius, mass, present, p)
    b = robot_contacts_cell_list(pos, vel, radius, mass, present, p)
    assert (a[0] - pos).abs().max() > 0.05
    torch.testing.assert_close(b[0], a[0], **CROWD_TOL)  # as test_broad_phase.py
    torch.testing.assert_close(b[1], a[1], **CROWD_TOL)


def _err(a, b):
    return max(float((x - y).abs().max()) for x, y in zip(a, b) if x.dtype.is_floating_point)


@needs_triton
def test_triton_broad_phase_matches_the_reference_at_1000(interpret):
    E, N, arena = 2, 1000, 22.0
    pos, vel, radius, mass, present = crowd(E=E, N=N, arena=arena, seed=11)
    obst = _obstacles(E, 40, arena)
    p = WorldParams(arena=arena)  # N >= broad_phase_min_robots: the cell kernel, as the reference
    assert N >= p.broad_phase_min_robots and not cell_overflow(pos, present, p).any()
    cells = collide(pos, vel, radius, mass, present, *obst, p)
    dense = collide(
        pos, vel, radius, mass, present, *obst, replace(p, broad_phase_min_robots=10**9)
    )
    b = tt.collide_triton(pos, vel, radius, mass, present, *obst, p)
    assert (cells[0] - pos).abs().max() > 0.05
    torch.testing.assert_close(b[0], cells[0], **TOL)
    torch.testing.assert_close(b[1], cells[1], **TOL)
    # the dense solver's x_i sum_j c_ij - sum_j c_ij x_j loses digits at x ~ 20 m (2e-4 here):
    # the kernel is no farther from it than the reference's own broad phase
    assert _err(b, dense) <= _err(cells, dense) + 1e-5


@needs_triton
def test_ticks_at_1000_robots_agree_with_the_reference(interpret):
    inp, p = _world("swarm1000", 1, seed=2, absent=0.05)
    s = reset(inp.layout, inp.robots, p)
    # squeeze the swarm towards the centre so that many robots overlap
    c = p.arena / 2
    s = s._replace(pos=c + (s.pos - c) * 0.35)
    assert not cell_overflow(s.pos, inp.robots.present, p).any()  # reference's cells exact
    dense = replace(p, broad_phase_min_robots=10**9)
    for t in range(2):
        a = step(s, *inp, p)  # the reference, with its broad phase at N = 1000
        b = tt.step_triton(s, *inp, p)
        _compare(a, b, f"tick {t + 1}")
        d = step(s, *inp, dense)  # and with its dense solver: as above, no farther from it
        for name, x, y in zip(a._fields, d, b):
            if not x.dtype.is_floating_point:
                assert torch.equal(x, y), (t, name)
        assert _err(b, d) <= _err(a, d) + 1e-5
        if t == 0:
            assert (a.pos - s.pos).abs().max() > 0.05
        s = a


# ------------------------------------------------------------------ CUDA (-m gpu)
@pytest.mark.gpu
@needs_triton
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_compiled_kernels_on_cuda_agree_with_the_reference(monkeypatch):
    monkeypatch.delenv("TRITON_INTERPRET", raising=False)
    dev = torch.device("cuda")
    for name, E, ticks in (("four-niche", 8, 100), ("swarm200", 4, 30), ("swarm1000", 2, 6)):
        _, layout, rob, tables, p = random_world(name, E=E, seed=1, device=dev)
        inp = TickInputs(
            layout,
            rob,
            compatible(layout, rob, p),
            random_keys(layout, rob.radius.shape[1]),
            tables,
        )
        s = reset(layout, rob, p)
        assert tt.available(dev)
        for t in range(ticks):
            a = step(s, *inp, p)
            b = tt.step_triton(s, *inp, p)
            for f, x, y in zip(a._fields, a, b):
                if x.dtype.is_floating_point:
                    torch.testing.assert_close(y, x, rtol=1e-4, atol=1e-4)
                else:
                    assert torch.equal(x, y), (name, t, f)
            s = a


# ------------------------------------------------------------------ compiled, without a GPU
def _compile_sm90(fn, signature, constexprs, num_warps):
    from triton.backends.compiler import GPUTarget
    from triton.compiler import ASTSource, compile

    src = ASTSource(fn=fn, signature=signature, constexprs=constexprs)
    opts = {"num_warps": num_warps, "enable_fp_fusion": False}
    return compile(src, target=GPUTarget("cuda", 90, 32), options=opts)


@needs_triton
def test_the_kernels_compile_for_a_gpu_without_one(monkeypatch, tmp_path):
    """The interpreter runs Python and accepts what compiled Triton may not: each kernel, as
    the tick launches it, compiled for sm_90 (triton's own ptxas; no GPU, no driver)."""
    import triton.backends

    if "nvidia" not in triton.backends.backends:
        pytest.skip("triton has no nvidia backend here")
    monkeypatch.delenv("TRITON_INTERPRET", raising=False)
    monkeypatch.setenv("TRITON_CACHE_DIR", str(tmp_path))
    import triton.language as tl
    from triton.runtime.interpreter import InterpretedFunction

    if isinstance(tl.sum, InterpretedFunction):
        pytest.skip("this process imported triton under the interpreter")
    k = tt._kernels()
    f, i64, u8 = "*fp32", "*i64", "*u8"
    common = dict(pos_ptr=f, vel_ptr=f, radius_ptr=f, mass_ptr=f, present_ptr=u8)
    static = dict(o_pos_ptr=f, o_rad_ptr=f, o_pres_ptr=u8)
    out = dict(out_pos_ptr=f, out_vel_ptr=f)
    dense = {**common, **static, **out, "N": "i32", "O": "i32", "arena": "fp32"}
    b = tt.dense_blocks(200, 40)
    w = b.pop("num_warps")
    dense.update({name: "constexpr" for name in ("ITERS", *b)})
    assert _compile_sm90(k.collide_dense_kernel, dense, {"ITERS": 3, **b}, w).asm["cubin"]
    cells = {**common, "cell_ptr": i64, "order_ptr": i64, "start_ptr": i64, **static, **out}
    cells.update({"N": "i32", "O": "i32", "G": "i32", "arena": "fp32"})
    b = tt.cells_blocks(1000, 40)
    w = b.pop("num_warps")
    cells.update({name: "constexpr" for name in ("PAIRS", "VEL", "STATIC", *b)})
    consts = {"PAIRS": True, "VEL": True, "STATIC": True, **b}
    assert _compile_sm90(k.collide_cells_kernel, cells, consts, w).asm["cubin"]
    sense_sig = dict(pos_ptr=f, gpos_ptr=f, avail_ptr=u8, free_ptr=u8, compat_ptr=u8)
    sense_sig.update(keys_ptr=f, best_ptr=i64, best_d_ptr=f, rand_ptr=i64, rand_d_ptr=f)
    sense_sig.update(N="i32", H="i32", INF="fp32", BI="constexpr", BH="constexpr")
    b = tt.sense_blocks(200, 144)
    w = b.pop("num_warps")
    assert _compile_sm90(k.sense_kernel, sense_sig, b, w).asm["cubin"]
