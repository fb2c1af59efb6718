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

from .app.analysis import replay_run, run_dynamics
from .app.api import RunResult, evolve, load, resume
from .app.evaluate import EvaluationResult, evaluate
from .app.load_runs import Runs, load_runs
from .app.reporter import Reporter
from .app.reporting import composition_figure
from .coevo.ask_tell import Asked, Evolution
from .coevo.config import SwarmCoDeConfig
from .coevo.evolve import GenerationResult
from .coevo.population import Population
from .sim.bt import format_tree
from .sim.scenario import Scenario, builtin_names, load_scenario
from .sim.worlds import World, generate_world, split_seeds, study_worlds, world_toml
from .version import __version__

__all__ = [
    "evolve",
    "resume",
    "load",
    "load_runs",
    "Runs",
    "RunResult",
    "Reporter",
    "SwarmCoDeConfig",
    "Evolution",
    "Asked",
    "GenerationResult",
    "Population",
    "load_scenario",
    "builtin_names",
    "Scenario",
    "generate_world",
    "World",
    "world_toml",
    "study_worlds",
    "split_seeds",
    "composition_figure",
    "replay_run",
    "run_dynamics",
    "evaluate",
    "EvaluationResult",
    "format_tree",
    "__version__",
]
