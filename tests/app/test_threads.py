"""--threads and threads=: the CLI and the API check the count and set torch's threads (the
simulator's thread rule itself, `sim.runtime.set_threads`, is tested in tests/sim/test_fused.py)."""

import pytest
import torch
from typer.testing import CliRunner

from swarmcode_torch.app import api
from swarmcode_torch.app.cli import app


def test_cli_and_api_take_threads(tmp_path):
    before = torch.get_num_threads()
    try:
        r = CliRunner().invoke(app, ["evolve", "--threads", "0", "--logdir", str(tmp_path)])
        assert r.exit_code != 0 and "--threads must be an integer >= 1" in r.output
        r = CliRunner().invoke(app, ["sweep", "--threads", "0", "--out", str(tmp_path / "s")])
        assert r.exit_code != 0 and "--threads must be an integer >= 1" in r.output
        res = api.evolve(
            scenario="one-niche",
            population=4,
            generations=1,
            trials=1,
            ticks=10,
            logdir=None,
            threads=1,
        )
        assert torch.get_num_threads() == 1 and len(res.history) == 1
        with pytest.raises(ValueError, match="threads"):
            api.evolve(scenario="one-niche", population=4, generations=1, logdir=None, threads=0)
    finally:
        torch.set_num_threads(before)
