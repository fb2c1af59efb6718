"""Helpers shared by the benchmark scripts: device and run metadata, timing, JSON output."""

from __future__ import annotations

import json
import os
import platform
import shlex
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import torch

BENCH_DIR = Path(__file__).resolve().parent
RESULTS_DIR = BENCH_DIR / "results"


def git_commit(short: bool = True) -> str:
    """The repository's HEAD commit (short form by default), or "unknown"."""
    cmd = ["git", "rev-parse", "--short", "HEAD"] if short else ["git", "rev-parse", "HEAD"]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, check=True, cwd=BENCH_DIR)
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def git_dirty() -> bool | None:
    """Whether the working tree has uncommitted changes to tracked files (None if unknown)."""
    try:
        out = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            check=True,
            cwd=BENCH_DIR,
        )
        return bool(out.stdout.strip())
    except (OSError, subprocess.CalledProcessError):
        return None


def cpu_name() -> str:
    """The CPU model from /proc/cpuinfo (else what platform knows)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def device_name(device: torch.device) -> str:
    """A human-readable name of the device: the GPU's name on CUDA, the CPU model otherwise."""
    if device.type == "cuda":
        return torch.cuda.get_device_name(device)
    return cpu_name()


def sync(device: torch.device) -> None:
    """Wait for queued kernels (CUDA); a no-op on CPU."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def now(device: torch.device) -> float:
    """perf_counter() after synchronizing the device, for wall-clock timing of GPU work."""
    sync(device)
    return time.perf_counter()


def load_average() -> list[float] | None:
    """1, 5 and 15 minute load averages (None where unavailable)."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (OSError, AttributeError):
        return None


def add_run_options(parser) -> None:
    """The --threads and --cold-compile options that `apply_run_options` applies."""
    parser.add_argument(
        "--cold-compile",
        action="store_true",
        help="disable inductor's caches, so compile_seconds is a cold compile "
        "(otherwise a repeated run reuses cached kernels and compiles faster)",
    )
    parser.add_argument("--threads", type=int, default=None, help="torch CPU threads")


def apply_run_options(parser, args) -> torch.device:
    """Apply the --threads and --cold-compile options; the --device, checked to exist."""
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.cold_compile:
        from torch._inductor import config as inductor_config

        inductor_config.force_disable_caches = True
    device = torch.device(args.device)
    if device.type == "cuda" and not torch.cuda.is_available():
        parser.error("--device cuda but CUDA is not available")
    return device


def run_metadata(device: torch.device) -> dict[str, Any]:
    """What a result needs to be reproduced and compared: machine, software, command line."""
    meta: dict[str, Any] = {
        "device": str(device),
        "device_name": device_name(device),
        "cpu_name": cpu_name(),
        "cpu_count": os.cpu_count(),
        "torch": torch.__version__,
        "python": platform.python_version(),
        "threads": torch.get_num_threads(),
        "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
        "git_commit": git_commit(),
        "git_dirty": git_dirty(),
        "command": shlex.join([Path(sys.executable).name, *sys.argv]),
        "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "load_average_at_start": load_average(),
    }
    if device.type == "cuda":
        meta["cuda"] = torch.version.cuda
    return meta


def median(xs: list[float]) -> float:
    return statistics.median(xs)


def write_json(data: dict[str, Any], path: Path | str) -> Path:
    """Write data as indented JSON (creating the folder); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=2) + "\n")
    return path


def int_list(text: str) -> list[int]:
    """'50,200,400' -> [50, 200, 400] (argparse type)."""
    try:
        return [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"expected comma-separated integers, got {text!r}") from None


def parse_configs(text: str) -> list[tuple[str, int, int]]:
    """'four-niche:20:50,swarm200:200:50' -> [(scenario, swarm size, population), ...]."""
    out = []
    for item in text.split(","):
        name, swarm, pop = item.split(":")
        out.append((name, int(swarm), int(pop)))
    return out
