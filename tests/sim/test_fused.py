"""The fused C++ tick (`sim.fused`) against the Python tick, its reference.

From the same state, one tick of each gives the same discrete outcome (who holds what, package
statuses, stuck counters, waypoints redrawn) and floats equal to rounding (relative 1e-4; the
contact solver sums pairs in another order). Over many ticks the two drift apart as any two
float orders do in contact dynamics, so whole rollouts are compared in distribution elsewhere
(benchmarks/README.md), not here. The physics invariants run on both ticks in test_world.py.
"""

import warnings

import pytest
import torch
from worldkit import random_world

from swarmcode_torch.sim import native as native_mod
from swarmcode_torch.sim.fused import FusedTicks
from swarmcode_torch.sim.rollout import rollout
from swarmcode_torch.sim.runtime import tick_function, tick_mode
from swarmcode_torch.sim.state import Robots, State, TickInputs, compatible, random_keys, reset
from swarmcode_torch.sim.step import step

fused = FusedTicks()
needs_build = pytest.mark.skipif(
    not fused.ready(warn=False), reason="the fused C++ tick cannot be built here"
)


def _inputs(layout, rob, tables, p):
    return TickInputs(
        layout, rob, compatible(layout, rob, p), random_keys(layout, rob.radius.shape[1]), tables
    )


def _world(name, E, seed, absent=0.0):
    s, layout, rob, tables, p = random_world(name, E=E, seed=seed)
    if absent:  # padding slots, and robots with empty batteries
        g = torch.Generator().manual_seed(seed + 1)
        present = torch.rand(rob.radius.shape, generator=g) >= absent
        rob = rob._replace(present=present)
    return layout, rob, tables, p


def _compare(a: State, b: State, what: str):
    for name, x, y in zip(a._fields, a, b):
        if x.dtype.is_floating_point:
            assert torch.allclose(x, y, rtol=1e-4, atol=1e-4), (what, name, (x - y).abs().max())
        else:
            assert torch.equal(x, y), (what, name, (x != y).sum())


@needs_build
@pytest.mark.parametrize(
    "name,E,absent",
    [("four-niche", 8, 0.0), ("budget", 6, 0.3), ("two-niche", 4, 0.0), ("swarm200", 2, 0.1)],
)
def test_one_tick_agrees_with_the_python_tick_from_every_state(name, E, absent):
    layout, rob, tables, p = _world(name, E, seed=4, absent=absent)
    inp = _inputs(layout, rob, tables, p)
    s = reset(layout, rob, p)
    ticks = 150 if rob.radius.shape[1] < 100 else 40
    for t in range(ticks):
        a = step(s, *inp, p)
        _compare(a, fused.run_ticks(s, inp, p, 1), f"tick {t + 1}")
        if t == ticks // 2:  # some robots run out of energy
            a = a._replace(energy=torch.where(torch.rand(a.energy.shape) < 0.2, 0.0, a.energy))
        s = a


@needs_build
def test_many_ticks_in_one_call_equal_one_by_one_and_threads_change_nothing():
    layout, rob, tables, p = _world("four-niche", 6, seed=2, absent=0.1)
    inp = _inputs(layout, rob, tables, p)
    s0 = reset(layout, rob, p)
    one = s0
    for _ in range(60):
        one = fused(one, *inp, p)
    threads = torch.get_num_threads()
    try:
        outs = []
        for n in (1, 2):
            torch.set_num_threads(n)
            outs.append(fused.run_ticks(s0, inp, p, 60))
    finally:
        torch.set_num_threads(threads)
    for a, b, c in zip(one, *outs):
        assert torch.equal(a, b) and torch.equal(a, c)
    assert int(outs[0].t) == 60
    assert torch.equal(s0.pos, reset(layout, rob, p).pos)  # the input state is not changed


@needs_build
def test_rollout_and_tick_function_use_it_on_the_cpu(monkeypatch):
    fn, compiled = tick_function(torch.device("cpu"))
    assert isinstance(fn, FusedTicks) and not compiled and tick_mode(fn, compiled) == "fused"
    fn, compiled = tick_function(torch.device("cpu"), compile=False)
    assert isinstance(fn, FusedTicks)
    fn, compiled = tick_function(torch.device("cpu"), compile=True)  # asked for: torch.compile
    assert not isinstance(fn, FusedTicks) and compiled
    monkeypatch.setenv("SWARMCODE_TICK", "reference")
    fn, compiled = tick_function(torch.device("cpu"), generations=5)
    assert fn is step and not compiled and tick_mode(fn, compiled) == "eager"
    monkeypatch.setenv("SWARMCODE_TICK", "bogus")
    with pytest.raises(ValueError, match="SWARMCODE_TICK"):
        tick_function(torch.device("cpu"))
    monkeypatch.delenv("SWARMCODE_TICK")
    layout, rob, tables, p = _world("one-niche", 2, seed=1)
    m = rollout(layout, rob, tables, p, 30, step_fn=fused)
    assert all(torch.isfinite(v).all() for v in m.values())


def test_without_a_compiler_the_python_tick_runs(monkeypatch):
    monkeypatch.setattr(native_mod, "_module", None)
    monkeypatch.setattr(
        native_mod, "_error", RuntimeError("Error building extension\nc++: not found")
    )
    fn, compiled = tick_function(torch.device("cpu"), generations=5)
    assert fn is step and not compiled  # with a warning, the choice as before
    f = FusedTicks()
    layout, rob, tables, p = _world("one-niche", 1, seed=0)
    with pytest.warns(RuntimeWarning, match="fused C\\+\\+ tick could not be built .*not found"):
        m1 = rollout(layout, rob, tables, p, 5, step_fn=f)
    m2 = rollout(layout, rob, tables, p, 5, step_fn=step)
    for k in m1:
        assert torch.equal(m1[k], m2[k])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # said once
        rollout(layout, rob, tables, p, 2, step_fn=f)


@needs_build
def test_inputs_it_does_not_take_run_the_python_tick():
    layout, rob, tables, p = _world("one-niche", 1, seed=0)
    inp = _inputs(layout, rob, tables, p)
    s = reset(layout, rob, p)
    s64 = s._replace(pos=s.pos.double(), vel=s.vel.double())  # not float32: the reference
    a = FusedTicks(fallback=lambda st, *rest: "python").run_ticks(s64, inp, p, 1)
    assert a == "python"
    rob2 = Robots(*rob)
    assert rob2.radius.dtype == torch.float32


# ------------------------------------------------------------------ threads (--threads, threads=)
def test_default_threads_leave_the_loaded_cores_alone(monkeypatch):
    import os

    from swarmcode_torch.sim import runtime

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    for load, want in ((0.0, 2), (0.6, 1), (0.4, 2), (2.5, 1), (9.0, 1)):
        monkeypatch.setattr(os, "getloadavg", lambda load=load: (load, 0.0, 0.0))
        assert runtime.default_threads() == want
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(range(8)), raising=False)
    monkeypatch.setattr(os, "getloadavg", lambda: (3.2, 0.0, 0.0))
    assert runtime.default_threads() == 5


def test_set_threads(monkeypatch):
    from swarmcode_torch.sim.runtime import set_threads

    before = torch.get_num_threads()
    try:
        assert set_threads(1) == 1 and torch.get_num_threads() == 1
        monkeypatch.setenv("OMP_NUM_THREADS", "1")
        torch.set_num_threads(1)
        assert set_threads(None) == 1  # the environment's choice stands
        monkeypatch.delenv("OMP_NUM_THREADS")
        assert set_threads(None) >= 1
        for bad in (0, -2, 1.5, True):
            with pytest.raises(ValueError, match="threads must be an integer >= 1"):
                set_threads(bad)
    finally:
        torch.set_num_threads(before)
