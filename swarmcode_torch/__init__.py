"""swarmcode-torch: SwarmCoDe in PyTorch, co-evolving the behavior trees and hardware of
heterogeneous robot swarms.

    import swarmcode_torch as sc

    result = sc.evolve(scenario="four-niche", generations=20, population=30, seed=0)
    result.best_team["fitness"], result.run_dir      # runs/four-niche__0__<time>
    result.to_pandas()                               # one row per generation (needs pandas)
    sc.resume(result.run_dir, generations=40)

`evolve`, `resume`, `load` and `RunResult` are `swarmcode_torch.api`'s; the command line is
`swarmcode-torch` (or `python -m swarmcode_torch`). Importing the package loads torch and the
algorithm, not matplotlib, TensorBoard or the CLI's libraries: they load when first used.
"""

__version__ = "0.2.0"

import inspect as _inspect
import types as _types

from . import evolve as _evolve_module
from .api import RunResult, load, resume
from .api import evolve as _evolve
from .evolve import Evolution, EvolveConfig
from .scenario import Scenario, load_scenario


class _CallableModule(_types.ModuleType):
    """`swarmcode_torch.evolve` is both the module evolve.py (`from swarmcode_torch.evolve import
    EvolveConfig`, `import swarmcode_torch.evolve as E` keep working) and, called, the API's
    `swarmcode_torch.api.evolve`."""

    def __call__(self, *args, **kwargs) -> RunResult:
        return _evolve(*args, **kwargs)


_evolve_module.__class__ = _CallableModule
_evolve_module.__signature__ = _inspect.signature(_evolve)
_evolve_module.__doc__ = (f"{_evolve_module.__doc__ or ''}\n\nCalled, `swarmcode_torch.evolve(...)` "
                          f"is `swarmcode_torch.api.evolve`: {_evolve.__doc__}")
evolve = _evolve_module

__all__ = ["evolve", "resume", "load", "RunResult", "EvolveConfig", "Evolution", "load_scenario",
           "Scenario", "__version__"]
