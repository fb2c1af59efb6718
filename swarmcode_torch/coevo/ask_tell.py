"""Ask / tell: a generation split at its evaluation, so that a script can evaluate the teams
itself (its own simulator, a cluster, a cache) and hand the results back.

    ev = Evolution(cfg)
    while not ev.done:
        asked = ev.ask()                 # the teams this generation evaluates, and their seeds
        metrics = asked.evaluate()       # the built-in evaluation; or any other source
        result = ev.tell(metrics)        # the generation finishes: fitness, species, offspring

`ask` runs the generation's speciation and evaluation plan (partners, teams, environments) and
stops before the simulation; `tell` finishes it with the given per-environment metrics. A
generation computes from its state alone (the run's generator state is part of it), so `tell`
recomputes the plan `ask` returned, bit for bit, checks that it is the same, and goes on:
a run driven by `ask` / `tell` with `Asked.evaluate` gives exactly the results of `step`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch
from torch import Tensor

from ..sim.layout import Layout
from .evaluation import EvalPlan, sim_batch, simulate_batch
from .evolve import Evolution as _Evolution
from .evolve import GenerationResult, Hooks, generation
from .fitness import METRIC_KEYS
from .population import Population, design_record, genome_phenotype

#: The metrics `tell` needs of every team-episode (`rollout.episode_metrics` gives them and
#: more): those of the built-in fitness, and the energy the application's records report.
TELL_KEYS = (*METRIC_KEYS, "energy_used")


@dataclass(frozen=True, eq=False)
class Asked:
    """The teams one generation evaluates (`Evolution.ask`). B = the population's size: every
    individual has a focal team (itself and its partners) and a baseline team (its slots
    refilled from the partners), each run in the same `trials` environments.

    genome: the population [P] being evaluated; `focal_team`, `baseline_team` [B, S]: its rows
    per robot slot (-1: an empty slot); `seeds` [B * trials]: the seed of each environment,
    trial t of team i in row i * trials + t (`layouts`: the environments themselves).
    `tell` takes per-environment metrics [2 * B * trials]: every focal trial in that order, then
    every baseline trial (what `evaluate` returns)."""

    generation: int
    genome: Population
    focal_team: Tensor
    baseline_team: Tensor
    seeds: Tensor
    layouts: Layout
    trials: int
    plan: EvalPlan = field(repr=False)
    _ev: _Evolution = field(repr=False)

    @property
    def size(self) -> int:
        """B: the evaluations (one per individual)."""
        return int(self.focal_team.shape[0])

    @property
    def environments(self) -> int:
        """2 * B * trials: the length of each metric `tell` takes."""
        return 2 * self.size * self.trials

    def designs(self, team: Tensor) -> list[dict | None]:
        """The designs of a team's robots, one per slot.

        Args:
            team: a team's population rows, e.g. `asked.focal_team[i]`.

        Returns:
            Each slot's design (hardware, behavior tree, tag; `population.design_record`), None for
            an empty slot.
        """
        rows = [int(r) for r in team.tolist()]
        return [None if r < 0 else design_record(self.genome, r, -1, 0.0) for r in rows]

    def evaluate(self) -> dict[str, Tensor]:
        """The built-in evaluation of these teams: per-environment metrics [2 * B * trials]
        (`evaluation.simulate_batch`, or the run's evaluator: its shards), what `tell` takes."""
        ctx = self._ev.ctx
        if ctx.evaluator is not None:
            return ctx.evaluator.simulate(self.plan, self.genome)[0]
        metrics, _ = simulate_batch(
            sim_batch(self.plan, self.genome),
            ctx.params,
            ctx.eval_cfg.ticks,
            ctx.step_fn,
            None,
            ctx.scenario.hardware,
            genome_phenotype(self.genome, ctx.scenario.hardware),
        )
        return metrics


class _Asking(Exception):
    """Raised by the evaluator `ask` puts in place, once it has the plan: the generation stops
    there (it changes no state: `generation` builds a new one)."""

    def __init__(self, plan: EvalPlan, genome: Population):
        self.plan, self.genome = plan, genome


class _Catch:
    def simulate(self, plan: EvalPlan, genome: Population):
        raise _Asking(plan, genome)


class _Given:
    """The evaluator `tell` puts in place: the plan must be the one asked; the metrics given."""

    def __init__(self, asked: Asked, metrics: dict[str, Tensor], seconds: float):
        self.asked, self.metrics, self.seconds = asked, metrics, seconds

    def simulate(self, plan: EvalPlan, genome: Population):
        a = self.asked
        same = (
            torch.equal(plan.swarms.focal_team, a.focal_team)
            and torch.equal(plan.swarms.baseline_team, a.baseline_team)
            and torch.equal(plan.layouts.seed, a.seeds)
        )
        if not same:
            raise RuntimeError(
                "tell: the generation's teams are not those ask returned (the run's state "
                "changed between ask and tell)"
            )
        return self.metrics, self.seconds


def check_metrics(metrics, asked: Asked) -> dict[str, Tensor]:
    """`metrics` as `tell` uses them: a dict of float tensors [2 * B * trials] on the run's
    device, with every key of `TELL_KEYS`; TypeError / ValueError naming what is wrong."""
    if not isinstance(metrics, dict):
        raise TypeError(
            f"tell takes a dict of metric name -> tensor (what Asked.evaluate returns), "
            f"got {type(metrics).__name__}"
        )
    missing = [k for k in TELL_KEYS if k not in metrics]
    if missing:
        raise ValueError(f"tell: metrics missing: {', '.join(missing)}")
    n, dev = asked.environments, asked.focal_team.device
    out = {}
    for k, v in metrics.items():
        if not isinstance(v, Tensor):
            raise TypeError(f"tell: metric {k!r} must be a tensor, got {type(v).__name__}")
        if tuple(v.shape) != (n,):
            raise ValueError(
                f"tell: metric {k!r} has shape {tuple(v.shape)}, expected ({n},) "
                f"(2 * {asked.size} teams * {asked.trials} trials)"
            )
        v = v.to(device=dev, dtype=torch.float32)
        if not bool(torch.isfinite(v).all()):
            raise ValueError(f"tell: metric {k!r} holds NaN or infinite values")
        out[k] = v
    return out


class Evolution(_Evolution):
    """`coevo.evolve.Evolution` with `ask` and `tell` (the module's docstring): a generation run
    as ask, an evaluation of the caller's, tell. `step()` is unchanged (ask, the built-in
    evaluation and tell in one)."""

    _asked: Asked | None = None

    def ask(self) -> Asked:
        """The teams this generation evaluates (`Asked`); the state does not change until
        `tell`. Asking again before telling returns the same teams."""
        if self.done:
            raise RuntimeError(f"the run has done its {self.cfg.generations} generations")
        state, ctx = self.state, self.ctx
        keep = ctx.evaluator
        ctx.evaluator = _Catch()
        try:
            generation(state, ctx, Hooks())
        except _Asking as a:
            plan, genome = a.plan, a.genome
        else:  # pragma: no cover - generation always evaluates
            raise RuntimeError("the generation finished without an evaluation")
        finally:
            ctx.evaluator = keep
        self._asked = Asked(
            state.generation,
            genome,
            plan.swarms.focal_team,
            plan.swarms.baseline_team,
            plan.layouts.seed,
            plan.layouts,
            plan.trials,
            plan,
            self,
        )
        return self._asked

    def tell(self, metrics: dict[str, Tensor], sim_seconds: float = 0.0) -> GenerationResult:
        """Finish the generation `ask` started: fitness, species, admission, reproduction, as `step`.

        Args:
            metrics: the per-environment metrics of the asked teams (what `Asked.evaluate` returns,
                or the caller's own evaluation in the same layout).
            sim_seconds: the evaluation's wall time, for the records.

        Returns:
            The generation's `GenerationResult`; the new state is `self.state`.
        """
        asked = self._asked
        if asked is None or asked.generation != self.state.generation:
            raise RuntimeError("tell needs the teams of this generation: call ask() first")
        given = _Given(asked, check_metrics(metrics, asked), sim_seconds)
        keep = self.ctx.evaluator
        self.ctx.evaluator = given
        try:
            state, result = generation(self.state, self.ctx, self.hooks)
        finally:
            self.ctx.evaluator = keep
        self.state = state
        self._asked = None
        return result
