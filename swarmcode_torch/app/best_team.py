"""An honest best team: each generation's best team is re-evaluated on `reeval_trials` (K)
fresh environments, and the run's best team is the one of the highest re-evaluated mean, not
the luckiest single evaluation (issue #41).

**Why.** A generation's best team is the team of its fittest individual, scored once: the mean
over the run's `trials` environments (3 by default). The maximum of such scores over hundreds of
generations is mostly luck: a run recorded 1,722.5 for a team that a fresh episode scored 1,018,
and an early lucky team was never beaten.

**The re-evaluation.** Every generation, its best team (the teams.jsonl record) is scored on K
environments, one batch on the CPU (`team_eval.score_team`, what `evaluate` runs: the fused tick,
the run's fitness, its own score function when it has one), and the record gets
``"reeval": {"mean", "sd", "ci95": [low, high], "trials": K, "seeds": [first, last]}`` (the 95 %
Student t interval of the mean, `team_eval.INTERVAL`; sd and interval null for K = 1). A team
that is the run's best team already is not run again: the same team on the same environments
gives the same numbers.

**The environments.** Seeds `REEVAL_SEED_START` + i, i = 0 .. K - 1 (past the run's own seed
where that falls among them; `reeval_seeds`), each ``make_layouts(scenario, 1,
Generator().manual_seed(seed))``, as `evaluate` and `replay --seed` draw them: never drawn from
the run's own stream, and the same K for every candidate of the run, so that candidates are
compared on the same environments and a team kept from one generation to the next is not
re-rolled until it is lucky. `swarmcode-torch evaluate RUN --generation G --episodes K
--seed-start S` gives a record's numbers again; its default seeds (from 1,000,000) are held out
from this selection.

**The record.** The run's best team (`run_record.app_record(ev).best`, saved in the checkpoint
beside the algorithm's state) is the teams.jsonl record of the highest re-evaluated mean so far (the
earlier of equals), with ``fitness`` = that mean and ``single_trial_fitness`` = the team's own
single evaluation, and ``run_single_trial`` = {"fitness", "generation"}: the highest single
evaluation of any generation's best team (what the run recorded as its best before re-evaluation).
`--patience` counts generations since that record last changed. Evolution never reads any of it: a
run evolves the same for every K. K = 0: the best team is the highest single evaluation, as before
0.8 (configs written before the key resume with 0). A best team recorded with another K (a branch,
`evolve --from`, that changes it) is re-evaluated with this run's K first.
"""

from __future__ import annotations

import json
import math
import time
import weakref
from typing import Any

import torch

from ..coevo.evolve import Evolution
from ..sim import bt
from ..sim.layout import Layout
from ..sim.runtime import tick_function
from .run_record import app_record
from .team_eval import TEAM_GENES, draw_layouts, score_team

#: The first seed of the re-evaluation environments (`evaluate`'s default start is 1,000,000).
REEVAL_SEED_START = 2_000_000

#: The keys a re-evaluated best team record adds to its teams.jsonl record.
BEST_KEYS = ("single_trial_fitness", "run_single_trial")


def reeval_seeds(seed: int, k: int) -> range:
    """The seeds of a run's K re-evaluation environments: `REEVAL_SEED_START` on, or just past
    the run's own seed where that falls among them."""
    start = REEVAL_SEED_START
    if start <= seed < start + k:
        start = seed + 1
    return range(start, start + k)


def team_key(designs: list[dict]) -> str:
    """Two records are the same team when their designs, in order, make the same robots."""
    return json.dumps([[d.get(k) for k in TEAM_GENES] for d in designs])


class Reevaluator:
    """The re-evaluation of one run's teams (called with a team's designs, it returns the team's
    "reeval" record): the run's seeds, world, episode length and score function, the
    environments of the seeds once drawn, and the behavior-tree table of each program once
    built."""

    def __init__(self, ev: Evolution):
        self.cfg = ev.cfg
        self.k = ev.cfg.reeval_trials
        self.seeds = reeval_seeds(ev.cfg.seed, self.k)
        self.world = ev.ctx.scenario
        self.ticks = ev.ctx.eval_cfg.ticks
        self.score_fn = ev.ctx.score_fn
        self._layouts: dict[int, Layout] = {}  # robots -> the environments of the seeds
        self._tables: dict[tuple, torch.Tensor] = {}  # a program -> its behavior-tree table
        self._tick = None

    def tables(self, ops: torch.Tensor) -> torch.Tensor:
        """`bt.build_tables` of programs [D, L], each program's table built once (a run's best
        teams share most of their designs from one generation to the next)."""
        keys = [tuple(r) for r in ops.tolist()]
        new = sorted({i for i, k in enumerate(keys) if k not in self._tables})
        if new:
            if len(self._tables) + len(new) > 256:
                self._tables.clear()
                new = list(range(len(keys)))
            for i, t in zip(new, bt.build_tables(ops[new])):
                self._tables[keys[i]] = t
        return torch.stack([self._tables[k] for k in keys])

    def __call__(self, designs: list[dict]) -> dict:
        """The "reeval" record of a team (its designs, as teams.jsonl records them)."""
        robots = sum(int(d["count"]) for d in designs)
        if robots not in self._layouts:
            if len(self._layouts) >= 4:
                self._layouts.clear()
            self._layouts[robots] = draw_layouts(self.world, robots, self.seeds)
        if self._tick is None:
            self._tick, _ = tick_function(torch.device("cpu"), compile=False)
        s = score_team(
            designs,
            self.cfg,
            self.world,
            self.seeds,
            self.ticks,
            self.score_fn,
            self._layouts[robots],
            self._tick,
            self.tables,
        )
        return {
            "mean": s.mean,
            "sd": s.sd,
            "ci95": None if s.low is None else [s.low, s.high],
            "trials": s.n,
            "seeds": [self.seeds[0], self.seeds[-1]],
        }


_REEVALUATORS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def reevaluator(ev: Evolution) -> Reevaluator:
    """The run's `Reevaluator` (one per Evolution, kept while it lives)."""
    r = _REEVALUATORS.get(ev)
    if r is None or r.cfg is not ev.cfg:
        r = _REEVALUATORS[ev] = Reevaluator(ev)
    return r


def _as_best(team: dict, single: dict) -> dict:
    """A re-evaluated team record as the run's best team record."""
    return {
        **team,
        "fitness": team["reeval"]["mean"],
        "single_trial_fitness": team["fitness"],
        "run_single_trial": single,
    }


def _unreevaluated(best: dict) -> dict:
    """A best team record without its re-evaluation: its teams.jsonl record."""
    out = {k: v for k, v in best.items() if k not in BEST_KEYS and k != "reeval"}
    out["fitness"] = best.get("single_trial_fitness", best["fitness"])
    return out


def update(ev: Evolution, team: dict) -> tuple[dict, float]:
    """The run's best team record after generation `team` (its teams.jsonl record, which gets
    its "reeval" here), from `app_record(ev).best` (the record so far; see the module
    docstring), and
    the seconds the re-evaluation took."""
    k = ev.cfg.reeval_trials
    best = app_record(ev).best
    if k == 0:
        if best is not None and "reeval" in best:
            best = _unreevaluated(best)  # a branch that turned re-evaluation off
        return (team if best is None or team["fitness"] > best["fitness"] else best), 0.0
    t0 = time.perf_counter()
    score = reevaluator(ev)
    single = None
    if best is not None:
        single = best.get("run_single_trial") or {
            "fitness": best.get("single_trial_fitness", best["fitness"]),
            "generation": best["generation"],
        }
        if not _same_reeval(best.get("reeval"), score):
            # recorded without this run's re-evaluation (a branch that changed it)
            base = _unreevaluated(best)
            best = _as_best({**base, "reeval": score(base["designs"])}, single)
    if single is None or team["fitness"] > single["fitness"]:
        single = {"fitness": team["fitness"], "generation": team["generation"]}
    if best is not None and team_key(team["designs"]) == team_key(best["designs"]):
        team["reeval"] = dict(best["reeval"])
    else:
        team["reeval"] = score(team["designs"])
    if best is None or team["reeval"]["mean"] > best["fitness"]:
        best = _as_best(team, single)
    else:
        best = {**best, "run_single_trial": single}
    return best, time.perf_counter() - t0


def _same_reeval(reeval: Any, score: Reevaluator) -> bool:
    return (
        isinstance(reeval, dict)
        and reeval.get("trials") == score.k
        and reeval.get("seeds") == [score.seeds[0], score.seeds[-1]]
    )


def _number(v: Any) -> float | None:
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    return float(v) if ok else None


def figures(best: dict | None) -> dict[str, float | None]:
    """The run's best team as numbers (None where it has none): its fitness (the re-evaluated
    mean, or the single evaluation without re-evaluation), the bounds of its 95 % interval, the
    highest single evaluation of the run, its cost, species, niches and deliveries."""
    best = best or {}
    reeval = best.get("reeval") if isinstance(best.get("reeval"), dict) else {}
    ci = reeval.get("ci95") if isinstance(reeval.get("ci95"), list) else [None, None]
    single = best.get("run_single_trial")
    single = single.get("fitness") if isinstance(single, dict) else best.get("fitness")
    out = {
        "fitness": _number(best.get("fitness")),
        "fitness_ci_lo": _number(ci[0]) if len(ci) == 2 else None,
        "fitness_ci_hi": _number(ci[1]) if len(ci) == 2 else None,
        "single_trial_fitness": _number(single),
    }
    for key in ("cost", "species", "niches", "deliveries"):
        out[key] = _number(best.get(key))
    return out


def summary_fields(best: dict) -> dict:
    """summary.json's figures of the run's best team's re-evaluation (`best_fitness` is its
    mean): `best_fitness_sd`, `best_fitness_ci95` [low, high], `best_reeval_trials` (0: not
    re-evaluated), `best_reeval_seeds` [first, last], and the highest single evaluation of the
    run, `best_single_trial_fitness` in generation `best_single_trial_generation`."""
    reeval = best.get("reeval") if isinstance(best.get("reeval"), dict) else None
    single = best.get("run_single_trial") or {
        "fitness": best.get("fitness"),
        "generation": best.get("generation"),
    }
    return {
        "best_fitness_sd": reeval.get("sd") if reeval else None,
        "best_fitness_ci95": reeval.get("ci95") if reeval else None,
        "best_reeval_trials": reeval.get("trials", 0) if reeval else 0,
        "best_reeval_seeds": reeval.get("seeds") if reeval else None,
        "best_single_trial_fitness": single.get("fitness"),
        "best_single_trial_generation": single.get("generation"),
    }
