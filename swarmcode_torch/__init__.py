"""swarmcode-torch: SwarmCoDe in PyTorch, co-evolving the behavior trees and hardware of
heterogeneous robot swarms.

    import swarmcode_torch as sc

    result = sc.evolve(scenario="four-niche", generations=20, population=30, seed=0)
    result.best_team["fitness"], result.run_dir      # runs/four-niche__0__<time>
    result.to_pandas()                               # one row per generation (needs pandas)
    sc.resume(result.run_dir, generations=40)

`evolve`, `resume`, `load` and `RunResult` are `swarmcode_torch.app.api`'s; the command line is
`swarmcode-torch` (or `python -m swarmcode_torch`). Importing the package loads torch and the
algorithm, not matplotlib, TensorBoard or the CLI's libraries: they load when first used.
"""

__version__ = "0.2.0"

from .app.api import RunResult, evolve, load, resume
from .coevo.config import EvolveConfig, SwarmCoDeConfig
from .coevo.evolve import Evolution
from .sim.scenario import Scenario, load_scenario

__all__ = ["evolve", "resume", "load", "RunResult", "SwarmCoDeConfig", "EvolveConfig", "Evolution", "load_scenario",
           "Scenario", "__version__"]
