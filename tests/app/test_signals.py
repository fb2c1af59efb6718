"""A scheduler's stop: SIGTERM ends a run as Ctrl-C does, with its checkpoint written."""

import pytest
import torch
from test_cli import TINY, invoke, only_run


@pytest.mark.subprocess
def test_sigterm_writes_the_last_finished_generation(tmp_path):
    # a scheduler's stop (SIGTERM) acts as Ctrl-C: the run exits 143 with its checkpoint written
    import signal
    import subprocess
    import sys
    import time

    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "swarmcode_torch.app.cli",
            "evolve",
            *TINY,
            "--generations",
            "100000",
            "--checkpoint-every",
            "1000",
            "--log-every",
            "1",
            "--render-every",
            "0",
            "--device",
            "cpu",
            "--no-compile",
            "--logdir",
            str(tmp_path),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not any(tmp_path.glob("*/summary.json")):  # first generation finished
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.2)
        proc.send_signal(signal.SIGTERM)
        out, errs = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 143, errs
    assert "Terminated: checkpoint after generation" in errs and "Traceback" not in errs
    run = only_run(tmp_path)
    gen = torch.load(run / "checkpoint.pt", weights_only=True)["generation"]
    assert 1 <= gen < 100000
    r = invoke("evolve", "--resume", run, "--generations", gen + 1)
    assert r.exit_code == 0, r.output
