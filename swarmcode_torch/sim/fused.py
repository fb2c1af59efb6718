"""The fused CPU tick: `csrc/tick.cpp`, a hand-written C++ version of :func:`step.step` that
runs all of a rollout's ticks in one call, environment by environment, in parallel over
environments on torch's intra-op threads (``torch.set_num_threads``).

Built once and cached by `native` (a private folder keyed by a hash of the source, torch and
Python; a verified library; a build lock that a killed build cannot leave held). Where it cannot
be built or loaded (no compiler, a bad library), or for inputs it does not take (not on the CPU,
other dtypes), `FusedTicks` runs the Python tick instead and says so once.

The same extension holds `walk_tables`, the CPU walk of `bt.build_tables` (exact: integers).

The Python tick stays the reference: ``SWARMCODE_TICK=reference`` makes `tick_function` choose
it everywhere. The two agree to float rounding (tests/sim/test_fused.py; the tolerance is in
benchmarks/README.md): the contact solver sums its pairs in another order.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import torch

from .native import available, build_error, load_extension, tick_choice
from .state import State, TickInputs, WorldParams
from .step import step

__all__ = ["FusedTicks", "available", "build_error", "load_extension", "tick_choice"]


_STATE_DTYPES = (
    torch.long,
    torch.float32,
    torch.float32,
    torch.float32,
    torch.long,
    torch.long,
    torch.long,
    torch.float32,
    torch.float32,
    torch.float32,
    torch.long,
    torch.long,
    torch.bool,
    torch.long,
)


def _inputs(inputs: TickInputs) -> list[torch.Tensor] | None:
    layout, robots, compat, keys, tables = inputs
    want = [
        (layout.p_present, torch.bool),
        (layout.g_effector, torch.long),
        (layout.g_offset, torch.float32),
        (layout.p_mass, torch.float32),
        (layout.o_pos, torch.float32),
        (layout.o_radius, torch.float32),
        (layout.o_present, torch.bool),
        (robots.radius, torch.float32),
        (robots.mass, torch.float32),
        (robots.force, torch.float32),
        (robots.efficiency, torch.float32),
        (robots.present, torch.bool),
        (robots.program, torch.long),
        (compat, torch.bool),
        (keys, torch.float32),
        (tables, torch.int32),
    ]
    out = []
    for t, dt in want:
        if t.device.type != "cpu" or t.dtype != dt:
            return None
        out.append(t.contiguous())
    return out


def _params(p: WorldParams) -> tuple[list[float], list[int]]:
    import math

    lo, hi = 0.5, p.arena - 0.5
    fp = [
        p.arena,
        p.base_radius,
        p.dt,
        p.drag,
        p.v_cap,
        p.kp,
        p.kv,
        p.reach,
        p.near,
        p.idle_power,
        p.stuck_speed * p.dt,
        p.anchor_mass,
        p.rest_speed,
        p.cell_size,
        lo,
        hi - lo,
        p.arena / 2,
    ]
    ip = [
        p.stuck_ticks,
        p.waypoint_period,
        p.collision_iters,
        max(1, math.ceil(p.arena / p.cell_size)),
    ]
    return fp, ip


class FusedTicks:
    """A tick function for `rollout`: called like `step` it runs one tick; `run_ticks` runs many
    in one call. Falls back to `fallback` (default: the eager Python tick) per call for inputs
    the C++ tick does not take, and for good when the extension cannot be built."""

    def __init__(self, fallback: Callable | None = None):
        self.fallback = fallback or step
        self.warned = False

    @property
    def error(self) -> Exception | None:
        return build_error()

    def ready(self, warn: bool = True) -> bool:
        """Build (or load the cached build of) the extension; False, with a warning once, where
        it cannot be built."""
        if load_extension() is not None:
            return True
        if warn and not self.warned:
            self.warned = True
            err = build_error()
            lines = [ln.strip() for ln in str(err).splitlines() if ln.strip()]
            why = f"{type(err).__name__}: {lines[-1][:200]}" if lines else type(err).__name__
            warnings.warn(
                f"the fused C++ tick could not be built ({why}); running the Python tick",
                RuntimeWarning,
                stacklevel=3,
            )
        return False

    def _native(self, state: State, inputs: TickInputs):
        if state.pos.device.type != "cpu":
            return None
        ins = _inputs(inputs)
        if ins is None or any(t.dtype != d for t, d in zip(state, _STATE_DTYPES)):
            return None
        if not self.ready():
            return None
        return load_extension(), ins

    def run_ticks(self, state: State, inputs: TickInputs, params: WorldParams, ticks: int) -> State:
        inputs = TickInputs(*inputs)
        native = self._native(state, inputs)
        if native is None:
            for _ in range(ticks):
                state = self.fallback(state, *inputs, params)
            return state
        mod, ins = native
        prog = ins[12]
        if prog.numel() and (int(prog.min()) < 0 or int(prog.max()) >= ins[15].shape[0]):
            raise IndexError(f"robot programs index {ins[15].shape[0]} behavior-tree tables")
        st = [t.clone(memory_format=torch.contiguous_format) for t in state]
        fp, ip = _params(params)
        mod.run_ticks(st, ins, fp, ip, int(ticks))
        return State(*st)

    def __call__(self, state, layout, robots, compat, keys, tables, params):
        return self.run_ticks(state, TickInputs(layout, robots, compat, keys, tables), params, 1)
