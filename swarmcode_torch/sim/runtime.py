"""How the tick runs: the fused C++ tick on the CPU (`fused.FusedTicks`), compiled
(`CompiledStep`, eager fallback), replayed from CUDA graphs (`CudaGraphTicks`), the choice between
them for a run (`tick_function`, `tick_mode`), and the device of a run (`resolve_device`)."""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import torch

from .fused import FusedTicks, tick_choice
from .layout import Layout
from .state import Robots, State, TickInputs, WorldParams
from .step import step
from .triton_tick import TritonTicks

# compiling the tick takes ~10-20 s on a CPU and then runs it ~2.4x faster (benchmarks/README.md)
COMPILE_MIN_GENERATIONS = 50


class CompiledStep:
    """`torch.compile(step)`, falling back to eager `step` (with a warning) when the first call
    cannot compile, e.g. on a machine without the C++ compiler that inductor's CPU backend needs."""

    def __init__(self, **compile_kwargs: Any) -> None:
        self.compiled = torch.compile(step, dynamic=False, **compile_kwargs)
        self.fn: Callable | None = None  # the compiled or, once compiling failed, eager tick
        self.error: Exception | None = None

    def __call__(self, *args):
        if self.fn is None:
            try:
                out = self.compiled(*args)
                self.fn = self.compiled
                return out
            except Exception as e:  # noqa: BLE001 - any compiler failure means: run eager
                import warnings

                self.error, self.fn = e, step
                lines = [
                    ln.strip()
                    for ln in str(e).splitlines()
                    if ln.strip()
                    and not ln.strip().startswith(("Set TORCH", "For even more developer"))
                ]
                parts = [lines[0]] + ([lines[-1]] if len(lines) > 1 else []) if lines else []
                why = (
                    f"{type(e).__name__}: {' ... '.join(p[:160] for p in parts)}"
                    if parts
                    else type(e).__name__
                )
                warnings.warn(
                    f"torch.compile failed ({why}); running the tick eagerly",
                    RuntimeWarning,
                    stacklevel=2,
                )
        return self.fn(*args)


class CudaGraphTicks:
    """Run a rollout's ticks as replays of one captured CUDA graph of `ticks_per_graph` ticks.

    `step_fn` (typically a compiled `step`) is warmed up on a side stream, then captured with
    `torch.cuda.graph` on static copies of the state and of every input; each tick's output
    state is copied back into the static state inside the graph. A later rollout with the same
    shapes and params copies its inputs into the static buffers and replays: one launch per
    `ticks_per_graph` ticks instead of one per kernel. Different shapes or params recapture.
    Pass it as `step_fn` to `rollout`. CUDA only.
    """

    def __init__(
        self, step_fn: Callable | None = None, ticks_per_graph: int = 10, required: bool = True
    ):
        if not torch.cuda.is_available():
            raise RuntimeError("CUDA graphs need a CUDA device")
        if ticks_per_graph < 1:
            raise ValueError("ticks_per_graph must be >= 1")
        # the eager tick makes small host-to-device copies, which a capture does not allow
        if step_fn is None:
            step_fn = CompiledStep()
        self.step_fn: Callable = step_fn
        self.k = ticks_per_graph
        self.key: tuple | None = None  # the shapes and params of the captured graph
        self.graph: torch.cuda.CUDAGraph | None = None
        # required: a tick that fails to compile is an error; otherwise the ticks run one by one
        # with the step's eager fallback
        self.required = required
        self.disabled = False

    def __call__(self, *args):  # a single tick, outside any graph
        return self.step_fn(*args)

    @staticmethod
    def _tensors(state: State, inputs: TickInputs) -> list[torch.Tensor]:
        layout, robots, compat, keys, tables = inputs
        return [*state, *layout, *robots, compat, keys, tables]

    def _capture(self, state: State, inputs: TickInputs, params: WorldParams) -> None:
        if any(t.device.type != "cuda" for t in self._tensors(state, inputs)):
            raise ValueError("CudaGraphTicks needs every state and input tensor on the GPU")
        layout, robots, compat, keys, tables = inputs
        self.state = State(*(t.clone() for t in state))
        self.inputs = TickInputs(
            Layout(*(t.clone() for t in layout)),
            Robots(*(t.clone() for t in robots)),
            compat.clone(),
            keys.clone(),
            tables.clone(),
        )

        def ticks(n: int) -> None:
            for _ in range(n):
                out = self.step_fn(self.state, *self.inputs, params)
                for a, b in zip(self.state, out):
                    if a is not b:
                        a.copy_(b)

        side = torch.cuda.Stream()
        side.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(side):
            ticks(2)  # compile and allocate outside the capture
        torch.cuda.current_stream().wait_stream(side)
        if isinstance(self.step_fn, CompiledStep) and self.step_fn.error is not None:
            if self.required:
                raise RuntimeError(
                    "CudaGraphTicks needs the compiled tick, and compiling "
                    f"failed: {self.step_fn.error}"
                )
            self.disabled = True
            return
        self.graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(self.graph):
            ticks(self.k)

    def run_ticks(self, state: State, inputs: TickInputs, params: WorldParams, ticks: int) -> State:
        """`ticks` ticks from `state` (`inputs`: a `TickInputs` or a tuple in its order)."""
        key = (tuple((t.shape, t.dtype, t.device) for t in self._tensors(state, inputs)), params)
        if key != self.key and not self.disabled:
            self._capture(state, inputs, params)
            self.key = key
        if self.disabled:  # compiling failed and graphs were optional: tick by tick
            for _ in range(ticks):
                state = self.step_fn(state, *inputs, params)
            return state
        for a, b in zip(self._tensors(self.state, self.inputs), self._tensors(state, inputs)):
            a.copy_(b)
        assert self.graph is not None  # captured above or by an earlier call
        for _ in range(ticks // self.k):
            self.graph.replay()
        out = State(*(t.clone() for t in self.state))
        for _ in range(ticks % self.k):
            out = self.step_fn(out, *self.inputs, params)
        return out


def resolve_device(name: str) -> torch.device:
    """The torch device for 'auto' / 'cpu' / 'cuda[:i]'; ValueError when CUDA is missing."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise ValueError(f"device {name!r} was asked for, but no CUDA device is available")
    try:
        dev = torch.device(name)
    except RuntimeError:
        raise ValueError(f"device must be auto, cpu, cuda or cuda:N, got {name!r}") from None
    if dev.type == "cuda" and dev.index is not None and dev.index >= torch.cuda.device_count():
        raise ValueError(
            f"device {name!r}: there are only {torch.cuda.device_count()} CUDA devices"
        )
    return dev


def tick_function(
    device: torch.device,
    compile: bool | None = None,
    cuda_graphs: bool | None = None,
    generations: int = 0,
) -> tuple[Callable, bool]:
    """The tick function of a run on `device` and whether it is compiled. On the CPU, unless
    `compile` is true or ``SWARMCODE_TICK=reference``: the fused C++ tick (`FusedTicks`, which
    is built on first use; where it cannot be, a warning and the choice below), not compiled.
    ``SWARMCODE_TICK=triton`` (and `compile` and `cuda_graphs` not true): the tick with its
    pair phases in Triton kernels (`triton_tick.TritonTicks`), not compiled.
    Otherwise the Python
    tick: `compile` unset compiles it on CUDA, or for runs of at least COMPILE_MIN_GENERATIONS
    generations; `cuda_graphs` unset: on CUDA with the compiled tick, and a tick that fails to
    compile then runs eagerly."""
    choice = tick_choice()
    if choice == "triton" and compile is not True and not cuda_graphs:
        return TritonTicks(), False
    if device.type == "cpu" and compile is not True and not cuda_graphs and choice == "fused":
        fused = FusedTicks()
        if fused.ready(warn=True):
            return fused, False
    use_compile = (
        compile
        if compile is not None
        else (device.type == "cuda" or generations >= COMPILE_MIN_GENERATIONS)
    )
    if cuda_graphs and (device.type != "cuda" or not use_compile):
        raise ValueError("cuda_graphs needs device cuda and the compiled tick (compile)")
    step_fn: Callable = step
    if use_compile:
        step_fn = CompiledStep()
    graphs = cuda_graphs if cuda_graphs is not None else (device.type == "cuda" and use_compile)
    if graphs:  # unset (auto): a tick that fails to compile runs eagerly, as without graphs
        step_fn = CudaGraphTicks(step_fn, required=cuda_graphs is not None)
    return step_fn, use_compile


def tick_mode(step_fn: Callable, compiled: bool) -> str:
    """How the tick runs: 'fused', 'triton', 'eager', 'compiled', 'compiled, CUDA graphs', 'eager (compiling
    failed)' once a compiled tick has fallen back."""
    if isinstance(step_fn, FusedTicks):
        return "fused"
    if isinstance(step_fn, TritonTicks):  # it has warned once it fell back to the Python tick
        return "eager (the Triton tick could not run)" if step_fn.warned else "triton"
    graphs = isinstance(step_fn, CudaGraphTicks)
    compiled_step = step_fn
    if isinstance(step_fn, CudaGraphTicks):
        compiled_step = step_fn.step_fn
    if isinstance(compiled_step, CompiledStep) and compiled_step.error is not None:
        return "eager (compiling failed)"
    if graphs:
        return "compiled, CUDA graphs"
    return "compiled" if compiled else "eager"


# ---------------------------------------------------------------- CPU threads
def default_threads() -> int:
    """The CPU threads a run takes when it is not told: the cores this process may use less the
    machine's 1-minute load average (rounded), at least 1. On an idle 2-core machine that is 2;
    under a load of 2 or more, 1, because threads that wait for cores another process holds
    make the tick slower than one thread does (issue #30: 5.6 against 36-52 s a generation)."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    try:
        load = os.getloadavg()[0]
    except (AttributeError, OSError):
        load = 0.0
    return max(1, min(cores, int(cores - load + 0.5)))


#: The most CPU threads a process may ask for (far beyond the cores of any one machine: more
#: threads than cores only slow a run, and 10^5 of them crashed the process).
MAX_THREADS = 1024


def set_threads(threads: int | None = None) -> int:
    """Set torch's CPU threads (the fused tick runs environments in parallel on them) and return
    the number: `threads`, or unset: `OMP_NUM_THREADS` where the environment sets it (torch
    already follows it), else `default_threads()`. ValueError below 1 or above MAX_THREADS."""
    if threads is None:
        if os.environ.get("OMP_NUM_THREADS", "").strip():
            return torch.get_num_threads()
        threads = default_threads()
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads must be an integer >= 1, got {threads!r}")
    if threads > MAX_THREADS:
        raise ValueError(f"threads must be <= {MAX_THREADS}, got {threads}")
    torch.set_num_threads(threads)
    return threads
