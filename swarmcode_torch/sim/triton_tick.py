"""The tick with its pair phases in Triton kernels (issue #40): robot-robot contacts with
obstacles and walls (`contacts.collide`), and the robot x grip-point part of sensing
(`sense.sense`), without any [E, N, N] or [E, N, H] tensor in memory.

* `collide_triton`: for N below `WorldParams.broad_phase_min_robots` (and N <= DENSE_MAX_ROBOTS)
  one program per environment holds its N robots in registers and runs all the solver's
  passes, then obstacles and walls, in one launch (`collide_dense_kernel`). Larger swarms use
  the sorted cell list of `sim.cell_list` (torch ops, rebuilt every pass as the reference's
  broad phase) and one launch per pass over blocks of robots in cell order
  (`collide_cells_kernel`), which visits every robot of the 9 neighbouring cells: no per-cell
  capacity (the reference's `neighbour_candidates` sees 32 per cell).
* `sense_triton`: `sense` itself with the nearest and the preferred grip found by
  `sense_kernel` (its code over other globals: `nearest_grips` resolved to this module's); the
  leaf statuses from them as `sense` computes them.
* `step_triton`: `step.step` itself, with `sense` and `collide` resolved to the two above
  (the same function code over other globals, so it follows step.py as it changes); every
  other part of the tick is the reference's torch code. `TritonTicks` is it as a `step_fn`.

Triton is optional: this module imports without it, and the kernels are imported on first use.
They run where `available(device)`: CUDA with triton installed, or the CPU under Triton's
interpreter (``TRITON_INTERPRET=1``: slow, for tests). Agreement with the reference is that of
the fused C++ tick (tests/sim/test_triton_tick.py): equal integer state, floats to rounding
(the pair sums are summed in another order).

Not done here (no GPU figure exists yet, benchmarks/README.md): a whole tick in one kernel,
and `runtime.tick_function` choosing this tick.
"""

from __future__ import annotations

import contextlib
import importlib
import sys
import types
import warnings
from collections.abc import Callable, Iterator
from typing import Any

import torch

from .cell_list import cell_list_for
from .sense import _INF, sense
from .state import Robots, State, WorldParams
from .step import step

# the dense kernel holds an environment's robots in one block (a power of two) of registers
DENSE_MAX_ROBOTS = 1024
# Under the interpreter every op of every program costs about 0.1 ms of Python whatever its
# size, so there the kernels get the largest blocks (few programs, few loop steps); this makes
# them take the compiled kernels' block sizes instead (tests cover both: the loops over
# several chunks run only with the small ones).
GPU_BLOCKS_IN_INTERPRETER = False
_kmod: Any = None


def has_triton() -> bool:
    """Whether triton can be imported (without importing it)."""
    if sys.modules.get("triton") is not None:
        return True
    import importlib.util

    return importlib.util.find_spec("triton") is not None


def interpreting() -> bool:
    """Triton's interpreter is on (``TRITON_INTERPRET=1``, as triton reads it): kernels run in
    Python on CPU tensors. False without triton."""
    if not has_triton():
        return False
    knobs = importlib.import_module("triton.knobs")  # (triton ships no type information)
    return bool(knobs.runtime.interpret)


def available(device: torch.device | str) -> bool:
    """Whether the Triton tick runs on `device`: triton installed and CUDA, or the CPU under
    the interpreter (``TRITON_INTERPRET=1``)."""
    device = torch.device(device)
    if not has_triton():
        return False
    if device.type == "cuda":
        return not interpreting() and torch.cuda.is_available()
    return device.type == "cpu" and interpreting()


def _kernels():
    """The kernel module, (re)imported when ``TRITON_INTERPRET`` differs from its import's."""
    global _kmod
    if _kmod is None or _kmod.INTERPRET != interpreting():
        from . import _triton_kernels as k

        if k.INTERPRET != interpreting():
            k = importlib.reload(k)
        _kmod = k
    return _kmod


_MISSING = object()


@contextlib.contextmanager
def _restoring_triton_language() -> Iterator[None]:
    """Put back the attributes of triton.language's modules and patched classes that a launch
    changed (names it added stay: the interpreter adds its own globals to the modules of the
    functions it rewrites, and its cache of them needs those).

    Triton's interpreter patches triton.language for a launch and restores it after, but a call
    of an interpreted library function inside a kernel (tl.sum, tl.min, ...) patches
    triton.language.core again and never restores that (triton 3.9). Left so, compiled Triton
    in the same process (inductor's kernels on a GPU too) would fail to compile."""
    tl = importlib.import_module("triton.language")
    core = tl.core
    objs = [tl, core, tl.math, tl.standard]
    for name in ("tensor", "dtype", "condition", "tensor_descriptor_base"):
        if isinstance(getattr(core, name, None), type):
            objs.append(getattr(core, name))
    saved = [(o, dict(vars(o))) for o in objs]
    try:
        yield
    finally:
        for o, before in saved:
            now = dict(vars(o))
            for k, v in before.items():
                if now.get(k, _MISSING) is not v:
                    setattr(o, k, v)


def _launching() -> contextlib.AbstractContextManager:
    """Around kernel launches: under the interpreter, `_restoring_triton_language`."""
    return _restoring_triton_language() if interpreting() else contextlib.nullcontext()


def _p2(n: int, lo: int = 16) -> int:
    return max(lo, 1 << max(0, n - 1).bit_length())


def triton_cdiv(a: int, b: int) -> int:
    return -(-a // b)


def _large_blocks() -> bool:
    return interpreting() and not GPU_BLOCKS_IN_INTERPRETER


# Tiles of at most 8 elements a thread: compiled for sm_90, these use 141-215 registers and
# spill nothing (16 a thread spilled); to be tuned on a GPU.
def dense_blocks(N: int, O: int) -> dict[str, int]:
    """Launch sizes of `collide_dense_kernel` for N robots and O obstacles."""
    BN = _p2(N)
    if _large_blocks():
        return dict(BN=BN, BJ=BN, BO=min(_p2(O, 4), 256), num_warps=4)
    warps = min(8, max(1, BN // 32))
    BJ = max(1, 8 * 32 * warps // BN)
    return dict(BN=BN, BJ=BJ, BO=BJ, num_warps=warps)


def cells_blocks(N: int, O: int) -> dict[str, int]:
    """Launch sizes of `collide_cells_kernel`: BI robots a program, BK partners at a time."""
    if _large_blocks():
        return dict(BI=min(_p2(N), 1024), BK=32, BO=min(_p2(O, 4), 256), num_warps=4)
    return dict(BI=64, BK=8, BO=8, num_warps=4)


def sense_blocks(N: int, H: int) -> dict[str, int]:
    """Launch sizes of `sense_kernel`: BI robots a program, BH grip points at a time."""
    if _large_blocks():
        return dict(BI=min(_p2(N), 1024), BH=min(_p2(H), 128), num_warps=4)
    return dict(BI=min(_p2(N), 32), BH=min(_p2(H), 32), num_warps=4)


def _u8(t: torch.Tensor) -> torch.Tensor:
    """A bool tensor as uint8 (the kernels test != 0), contiguous."""
    return t.contiguous().view(torch.uint8) if t.dtype == torch.bool else t.contiguous()


def _f32(*ts: torch.Tensor) -> list[torch.Tensor]:
    """The tensors contiguous; TypeError unless float32 (the kernels compute in float32)."""
    bad = [t.dtype for t in ts if t.dtype != torch.float32]
    if bad:
        raise TypeError(f"the Triton kernels take float32 tensors, got {bad[0]}")
    return [t.contiguous() for t in ts]


def collide_triton(
    pos, vel, radius, mass, present, o_pos, o_radius, o_present, params: WorldParams
):
    """`contacts.collide` (same arguments and results) in Triton kernels."""
    k = _kernels()
    E, N = present.shape
    O = o_pos.shape[1]
    pos, vel, radius, mass, o_pos, o_radius = _f32(pos, vel, radius, mass, o_pos, o_radius)
    pres, o_pres = _u8(present), _u8(o_present)
    if E == 0 or N == 0:
        return pos.clone(), vel.clone()
    if N < params.broad_phase_min_robots and N <= DENSE_MAX_ROBOTS:
        out_pos = torch.empty_like(pos)
        out_vel = torch.empty_like(vel)
        with _launching():
            k.collide_dense_kernel[(E,)](
                pos,
                vel,
                radius,
                mass,
                pres,
                o_pos,
                o_radius,
                o_pres,
                out_pos,
                out_vel,
                N,
                O,
                float(params.arena),
                ITERS=int(params.collision_iters),
                **dense_blocks(N, O),
                enable_fp_fusion=False,
            )
        return out_pos, out_vel
    iters = int(params.collision_iters)
    blocks = cells_blocks(N, O)
    grid = (E, triton_cdiv(N, blocks["BI"]))
    p, v = pos, vel
    for it in range(max(iters, 1)):
        cl = cell_list_for(p, present, params)
        out_pos = torch.empty_like(pos)
        out_vel = torch.empty_like(vel)
        with _launching():
            k.collide_cells_kernel[grid](
                p,
                v,
                radius,
                mass,
                pres,
                cl.cell,
                cl.order,
                cl.start,
                o_pos,
                o_radius,
                o_pres,
                out_pos,
                out_vel,
                N,
                O,
                cl.grid,
                float(params.arena),
                PAIRS=iters > 0,
                VEL=it == 0,
                STATIC=it == max(iters, 1) - 1,
                **blocks,
                enable_fp_fusion=False,
            )
        p, v = out_pos, out_vel
    return p, v


def nearest_grips(pos, gpos, avail, free, compat, keys):
    """`sense.nearest_grips` (same arguments and results) in `sense_kernel`."""
    k = _kernels()
    E, N = free.shape
    H = gpos.shape[1]
    best = torch.zeros(E, N, dtype=torch.long, device=pos.device)
    rand = torch.zeros(E, N, dtype=torch.long, device=pos.device)
    best_d = torch.full((E, N), _INF, dtype=pos.dtype, device=pos.device)
    rand_d = torch.full((E, N), _INF, dtype=pos.dtype, device=pos.device)
    if E == 0 or N == 0 or H == 0:
        return best, best_d, rand, rand_d
    pos, gpos, keys = _f32(pos, gpos, keys)
    blocks = sense_blocks(N, H)
    with _launching():
        k.sense_kernel[(E, triton_cdiv(N, blocks["BI"]))](
            pos,
            gpos,
            _u8(avail),
            _u8(free),
            _u8(compat),
            keys,
            best,
            best_d,
            rand,
            rand_d,
            N,
            H,
            float(_INF),
            **blocks,
            enable_fp_fusion=False,
        )
    return best, best_d, rand, rand_d


def _rebind(fn: Callable, name: str, **names: Callable) -> Callable:
    """`fn`'s code over a copy of its globals with `names` replaced (each must be a global that
    the code reads, so a change of step.py or sense.py that drops one fails here, not
    silently)."""
    missing = [n for n in names if n not in fn.__code__.co_names or n not in fn.__globals__]
    if missing:
        raise RuntimeError(f"{fn.__qualname__} no longer reads {missing}: update triton_tick")
    g = dict(fn.__globals__)
    g.update(names)
    out = types.FunctionType(fn.__code__, g, name, fn.__defaults__, fn.__closure__)
    out.__kwdefaults__ = fn.__kwdefaults__
    module = fn.__module__.rsplit(".", 1)[-1]
    out.__doc__ = (
        f"`{module}.{fn.__name__}` with the pair phases in Triton kernels ({', '.join(names)})."
    )
    out.__qualname__ = name
    return out


#: `sense.sense` with the robot x grip-point phase in `sense_kernel` (`nearest_grips`)
sense_triton = _rebind(sense, "sense_triton", nearest_grips=nearest_grips)
step_triton = _rebind(step, "step_triton", sense=sense_triton, collide=collide_triton)


def takes(state: State, robots: Robots) -> bool:
    """Whether the kernels take these tensors: float32 positions and radii, on a device where
    `available`."""
    return (
        state.pos.dtype == torch.float32
        and robots.radius.dtype == torch.float32
        and robots.mass.dtype == torch.float32
        and available(state.pos.device)
    )


class TritonTicks:
    """A tick function for `rollout` (called like `step`): `step_triton` where the kernels run
    (`takes`), else `fallback` (default: the eager Python tick), saying so once."""

    def __init__(self, fallback: Callable | None = None):
        self.fallback = fallback or step
        self.warned = False

    def __call__(self, state, layout, robots, compat, keys, tables, params):
        if takes(state, robots):
            return step_triton(state, layout, robots, compat, keys, tables, params)
        if not self.warned:
            self.warned = True
            why = (
                "triton is not installed"
                if not has_triton()
                else f"not on a device it runs on ({state.pos.device}, {state.pos.dtype}; "
                "CUDA, or the CPU with TRITON_INTERPRET=1)"
            )
            warnings.warn(
                f"the Triton tick cannot run: {why}; running the Python tick",
                RuntimeWarning,
                stacklevel=2,
            )
        return self.fallback(state, layout, robots, compat, keys, tables, params)
