"""A run's team on fresh seeds (`swarmcode-torch evaluate RUN`, `swarmcode_torch.evaluate`), as
Stable-Baselines3's `evaluate_policy` scores a trained policy: the fitness of one team (or of
the K best) over N new environments, with its spread and a 95 % interval, deliveries per package
class, the team's cost, and what each of its designs contributes.

**The team.** `best`: summary.json's best team; `last`: the last generation's best team in
teams.jsonl; `generation=G`: generation G's (teams.jsonl); `top=K`: the K best distinct teams of
teams.jsonl by their recorded fitness (two records are the same team when their designs' genes
and robot counts are; ties go to the earlier generation).

**The seeds.** Episode i runs in the environment of seed ``seed_start + i`` (default
``seed_start`` 1,000,000), i = 0 .. N - 1: ``make_layouts(scenario, 1, Generator().manual_seed(seed))``,
the environment `replay --seed SEED` shows. The run's own seed drives its evolution (every
environment it scored teams in was drawn from its one generator, seeded by it); a range that
holds the run's seed is refused, so that no evaluation environment is drawn from the start of the
run's own stream. The run's seeds are small numbers (0, 1, ...) and the default start is far
above them.

**One batch.** Every episode of every team and of every knock-out team (below) is one
environment of one batch, run through one rollout (the fused C++ tick on the CPU, the eager tick on
CUDA): not a loop over seeds (`team_eval`, which a run's re-evaluation of its best teams runs
as well, `best_team`). Each environment is simulated on its own, so the numbers of an
episode do not depend on the batch it ran in (tests/app/test_evaluate.py checks the mean of N
episodes against N evaluations of one episode each), and the same run and options give the same
numbers on the same device.

**The score.** An episode's fitness is the team score the run ranked teams by: F_raw (the
run's fitness weights) times the budget penalty (the run's budget), divided by the cost for
objective `roi` (`evaluation.team_scores`), ungated: the "fitness" teams.jsonl records is the
mean of this over the run's trials. A run scored by a user function is evaluated with that
function only when it is given (`fitness=`).

**The interval.** A 95 % Student t interval of the mean: mean ± t(0.975, N - 1) · sd / √N, sd the
sample standard deviation (N - 1); none for one episode.

**The knock-outs.** A design's contribution is the team's fitness less that of the team with the
design knocked out, episode by episode in the same environment, averaged over the episodes (with
its t interval). The knocked-out team refills the design's slots as the algorithm built the
baseline team a focal was scored against (`partners.assemble_swarms`): from the team's other
designs (its partners), all of them given to the nearest by design distance (the run's
`partner_admission = "substitute"`, `speciation.design_distance` with the run's weights; the first
of equals in species order), or else drawn in proportion to dominance (uniformly when the run
has `dominance = false` or all are 0) with a generator seeded by the episode's seed (the draw of
`replay --html`). The team's focal design, where the record gives the baseline it was scored
against (`baseline_count`), is refilled as that baseline (as `replay --html` shows it). With no
other design, the knocked-out team has no robot. A design with no robot in the team has no
knock-out.

**The scenario.** The run's own (its scenario.toml and hardware.toml copies) and episode length,
or another (`scenario=`, a built-in name or a TOML file, read by `sim.scenario.load_scenario`:
its robots are built from that scenario's catalog, and its episode length applies), which must be
a world for at least the team's robots and whose catalog must build every design into a robot of
finite, positive mass and battery.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import torch
from torch import Tensor

from ..coevo.config import MAX_SEED, UPPER_BOUNDS
from ..coevo.evaluation import ScoreFn, score_fn_name, team_scores
from ..coevo.population import from_designs
from ..coevo.speciation import design_distance
from ..sim.runtime import resolve_device, set_threads
from ..sim.scenario import Scenario, ScenarioError, load_scenario
from .evaluate_teams import _check_team_fits, _Chosen, _recorded_baseline, _refill, choose_teams
from .files import RunError
from .runconfig import _size, memory_limit, read_config, run_scenario
from .team_eval import (  # noqa: F401 - Stat, t_quantile, INTERVAL: this module's API as well
    INTERVAL,
    TEAM_GENES,
    ProgressFn,
    Stat,
    draw_layouts,
    need_bytes,
    run_episodes,
    t_cdf,
    t_quantile,
    team_rows,
)

#: `draw_layouts` by the name tests and tools used before it moved to `team_eval`.
_layouts = draw_layouts

#: The episodes an evaluation runs by default, and at most.
DEFAULT_EPISODES = 20
MAX_EPISODES = 10_000
#: The first evaluation seed by default (see the module docstring).
DEFAULT_SEED_START = 1_000_000
#: The most teams `top` evaluates at once.
MAX_TOP = 100
TEAMS = ("best", "last")


# ------------------------------------------------------------------ results
@dataclass(frozen=True)
class Contribution:
    """What one design of the team contributes: its index in the team record's designs, its
    species, robots and effector, whether it is the record's focal design, how its slots were
    refilled (`refill`: "recorded baseline", "nearest partner", "dominance draw" or "no
    partner"), the knocked-out team's fitness and the contribution (team fitness less it),
    each over the episodes."""

    design: int
    species: int
    robots: int
    effector: str
    focal: bool
    refill: str
    knockout_fitness: Stat
    contribution: Stat

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["knockout_fitness"], d["contribution"] = (
            self.knockout_fitness.to_dict(),
            self.contribution.to_dict(),
        )
        return d


@dataclass(frozen=True)
class TeamEvaluation:
    """One team over the episodes: where it came from (`source`: "best", "last", "generation"
    or "top"; `generation`, `recorded_fitness`: the run's record of it), its robots, species and
    cost (in the evaluation's scenario), its fitness, the deliveries per package class (mean
    per episode; `deliveries`: one entry per class of the scenario, in its order, with its
    label and its packages an episode), all deliveries, each episode's fitness, and one
    `Contribution` per design with robots in the team."""

    source: str
    generation: int | None
    recorded_fitness: float | None
    robots: int
    species: int
    cost: float
    fitness: Stat
    deliveries: list[dict]
    deliveries_total: Stat
    episode_fitness: list[float]
    contributions: list[Contribution]

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["fitness"] = self.fitness.to_dict()
        d["deliveries_total"] = self.deliveries_total.to_dict()
        d["deliveries"] = [dict(x) for x in self.deliveries]
        d["contributions"] = [c.to_dict() for c in self.contributions]
        return d


@dataclass(frozen=True)
class EvaluationResult:
    """What `evaluate` returns: the evaluation's settings and one `TeamEvaluation` per team
    (one, or up to K with `top`, best first). `fitness`, `cost`, `deliveries` and
    `contributions` are the first team's. `to_dict()`: all of it as JSON-friendly data (what
    `swarmcode-torch evaluate --json` writes)."""

    run_dir: str
    selection: str  # "best", "last", "generation G" or "top K"
    scenario: str
    own_scenario: bool  # the run's own scenario (its copy), or another
    episodes: int
    seed_start: int
    seeds: tuple[int, int]  # the first and the last seed
    ticks: int
    device: str
    tick: str  # how the tick ran ("fused", "eager", ...)
    fitness_function: str  # "built-in" or "custom: module.qualname"
    interval: str
    teams: list[TeamEvaluation] = field(default_factory=list)

    @property
    def fitness(self) -> Stat:
        return self.teams[0].fitness

    @property
    def cost(self) -> float:
        return self.teams[0].cost

    @property
    def deliveries(self) -> list[dict]:
        return self.teams[0].deliveries

    @property
    def contributions(self) -> list[Contribution]:
        return self.teams[0].contributions

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["seeds"] = list(self.seeds)
        d["teams"] = [t.to_dict() for t in self.teams]
        return d


# ------------------------------------------------------------------ the evaluation
def _check_arguments(team, generation, top, episodes, seed_start, ticks) -> None:
    def is_int(v) -> bool:
        return isinstance(v, int) and not isinstance(v, bool)

    if team not in TEAMS:
        raise ValueError(f"team must be 'best' or 'last', got {team!r:.40}")
    if generation is not None and (not is_int(generation) or generation < 0):
        raise ValueError(f"generation must be an integer >= 0, got {generation!r:.40}")
    if top is not None and (not is_int(top) or not 1 <= top <= MAX_TOP):
        raise ValueError(f"top must be an integer in [1, {MAX_TOP}], got {top!r:.40}")
    if generation is not None and top is not None:
        raise ValueError("give generation or top, not both")
    if team != "best" and (generation is not None or top is not None):
        raise ValueError(f"team={team!r} and {'generation' if top is None else 'top'}: give one")
    if not is_int(episodes) or not 1 <= episodes <= MAX_EPISODES:
        raise ValueError(
            f"episodes must be an integer in [1, {MAX_EPISODES}], got {episodes!r:.40}"
        )
    if not is_int(seed_start) or not 0 <= seed_start <= MAX_SEED - episodes + 1:
        raise ValueError(
            f"seed_start must be an integer in [0, {MAX_SEED - episodes + 1}] (the last seed, "
            f"seed_start + episodes - 1, at most 2**63 - 1), got {seed_start!r:.40}"
        )
    if ticks is not None and (not is_int(ticks) or not 1 <= ticks <= UPPER_BOUNDS["ticks"]):
        raise ValueError(
            f"ticks must be an integer in [1, {UPPER_BOUNDS['ticks']}], got {ticks!r:.40}"
        )


def _seeds(run_dir: Path, cfg, fitness: ScoreFn | None, seed_start: int, episodes: int) -> range:
    """The evaluation seeds; RunError for a run scored by a custom function that is not given,
    or seeds that hold the run's own."""
    if cfg.fitness_function is not None and fitness is None:
        raise RunError(
            f"{run_dir} was scored by a custom fitness function ({cfg.fitness_function}): "
            "evaluate it from Python with the same function, "
            "swarmcode_torch.evaluate(run_dir, fitness=fn)"
        )
    seeds = range(seed_start, seed_start + episodes)
    if cfg.seed in seeds:
        raise RunError(
            f"the evaluation seeds {seeds[0]}..{seeds[-1]} hold the run's own seed {cfg.seed}; "
            f"start them past it (seed_start {cfg.seed + 1} or more)"
        )
    return seeds


def _scenario_and_teams(
    run_dir: Path, cfg, chosen: list[_Chosen], scenario: str | None, ticks: int | None
) -> tuple[Scenario, int, int]:
    """The scenario the teams run in (the run's own, or `scenario`), the robots of a team and
    the episode length; RunError where a team does not fit it or the teams differ in size."""
    if scenario is not None:
        world = load_scenario(scenario)  # ScenarioError (a ValueError) names the field
    else:
        try:
            world = run_scenario(run_dir, cfg)
        except ScenarioError as e:
            raise RunError(f"{run_dir}: its scenario cannot be loaded ({e})") from None
    for c in chosen:
        _check_team_fits(c.designs, world, scenario is None)
    robots = {sum(int(d["count"]) for d in c.designs) for c in chosen}
    if len(robots) > 1:
        raise RunError(
            f"the teams to evaluate have different sizes ({sorted(robots)} robots); "
            "evaluate them one by one"
        )
    if ticks is None:
        ticks = (cfg.ticks or world.episode_ticks) if scenario is None else world.episode_ticks
    return world, robots.pop(), ticks


def _knockout_batch(chosen: list[_Chosen], cfg, seeds: range) -> tuple:
    """Every design of every team in one genome, and the batch's teams [E, S]: per team, its
    episodes, then each knock-out's -> (genome, all designs, per team its knock-outs as
    (design, refill, [N, S]), teams)."""
    offsets, all_designs = [], []
    for c in chosen:
        offsets.append(len(all_designs))
        all_designs.extend(c.designs)
    genome, _ = from_designs(all_designs, cfg.tag_length)
    near_rule = cfg.partner_admission == "substitute"
    variants: list[list[tuple[int, str, Tensor]]] = []  # per team: (design, refill, [N, S])
    teams_rows: list[Tensor] = []
    for c, off in zip(chosen, offsets):
        local, team_t = team_rows(c.designs, cfg.tag_length)  # [S] design per slot
        near = design_distance(local, cfg.distance_weights) if near_rule else None
        focal, recorded = _recorded_baseline(c.designs, team_t)
        vs = []
        for d, rec in enumerate(c.designs):
            if int(rec["count"]) == 0:
                continue
            ko, how = _refill(
                c.designs,
                d,
                team_t,
                seeds,
                near,
                not cfg.dominance,
                recorded if d == focal else None,
            )
            vs.append((d, how, torch.where(ko >= 0, ko + off, -1)))
        variants.append(vs)
        teams_rows.append(team_t + off)
    blocks = []
    for t_rows, vs in zip(teams_rows, variants):
        blocks.append(t_rows.repeat(len(seeds), 1))
        blocks.extend(v for _, _, v in vs)
    return genome, all_designs, variants, torch.cat(blocks)


def _check_memory(E: int, S: int, n_teams: int, episodes: int, world: Scenario, dev) -> None:
    """RunError when the batch of E environments of S robots would not fit the device's memory."""
    need = need_bytes(E, S, episodes, world)
    limit, what = memory_limit(str(dev))
    if need > limit:
        raise RunError(
            f"{E} environments of {S} robots ({n_teams} team(s), their knock-outs, "
            f"{episodes} episodes) would need about {_size(need)} of memory, more than the "
            f"{_size(limit)} of {what}; evaluate fewer episodes"
        )


def _team_results(
    chosen: list[_Chosen],
    variants: list,
    scores: Tensor,
    cost: Tensor,
    per_class: Tensor,
    world: Scenario,
    episodes: int,
    robots: int,
) -> list[TeamEvaluation]:
    """One `TeamEvaluation` per team from the batch's episode scores, costs and deliveries per
    class (rows in `_knockout_batch`'s order)."""
    out, at = [], 0
    for c, vs in zip(chosen, variants):
        base = slice(at, at + episodes)
        f = scores[base]
        contributions = []
        for k, (d, how, _) in enumerate(vs):
            ko = scores[at + (k + 1) * episodes : at + (k + 2) * episodes]
            rec = c.designs[d]
            contributions.append(
                Contribution(
                    design=d,
                    species=int(rec["species"]),
                    robots=int(rec["count"]),
                    effector=str(rec["effector"]),
                    focal=rec.get("focal") is True,
                    refill=how,
                    knockout_fitness=Stat.of(ko),
                    contribution=Stat.of(f - ko),
                )
            )
        pc = per_class[base]
        out.append(
            TeamEvaluation(
                source=c.source,
                generation=c.generation,
                recorded_fitness=c.recorded_fitness,
                robots=robots,
                species=len({int(d["species"]) for d in c.designs if int(d["count"]) > 0}),
                cost=float(cost[at]),
                fitness=Stat.of(f),
                deliveries=[
                    {
                        "class": j,
                        "label": pk.label,
                        "packages": pk.count,
                        "mean": float(pc[:, j].mean()),
                    }
                    for j, pk in enumerate(world.packages)
                ],
                deliveries_total=Stat.of(pc.sum(1)),
                episode_fitness=[float(x) for x in f],
                contributions=contributions,
            )
        )
        at += episodes * (1 + len(vs))
    return out


# long: its docstring is the public API's parameter table (the docs' reference); the code is under 80 lines
def evaluate(
    run_dir: str | Path,
    team: str = "best",
    generation: int | None = None,
    top: int | None = None,
    episodes: int = DEFAULT_EPISODES,
    seed_start: int = DEFAULT_SEED_START,
    scenario: str | None = None,
    device: str = "cpu",
    *,
    ticks: int | None = None,
    fitness: ScoreFn | None = None,
    threads: int | None = None,
    progress: ProgressFn | None = None,
) -> EvaluationResult:
    """Evaluate a run's team on `episodes` fresh seeds, `seed_start` + i, all in one batch.

    The team, the seeds, the score, the interval and the knock-outs: this module's docstring.
    Reads the run directory and writes nothing.

    Args:
        run_dir: the run directory.
        team: "best" (summary.json's best team) or "last" (teams.jsonl's last generation).
        generation: evaluate that generation's best team instead.
        top: evaluate the K best distinct teams of teams.jsonl instead.
        episodes: how many fresh seeds.
        seed_start: the first seed (disjoint from the seeds a run uses).
        scenario: another scenario (a built-in name or a TOML file) instead of the run's own.
        device: "cpu" or "cuda".
        ticks: the episode length (default: the run's on its own scenario, else the scenario's).
        fitness: the run's user fitness function, for a run scored by one (any other ScoreFn
            scores the episodes with it).
        threads: torch's CPU threads (`evolve`'s rule when unset).
        progress: `progress(stage, done, total)`, called as the environments are drawn and the
            ticks run.

    Returns:
        An `EvaluationResult`: one `TeamEvaluation` per team, best first (`to_dict()` is the JSON
        `swarmcode-torch evaluate --json` writes).

    Raises:
        RunError: (a ValueError) a run, a team or a scenario that cannot be evaluated.
        ValueError: an argument out of range.
    """
    _check_arguments(team, generation, top, episodes, seed_start, ticks)
    if fitness is not None and not callable(fitness):
        raise TypeError(f"fitness must be a function, got {type(fitness).__name__}")
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunError(f"{run_dir} is not a run directory (no such directory)")
    dev = resolve_device(device)
    set_threads(threads)
    cfg = read_config(run_dir)
    seeds = _seeds(run_dir, cfg, fitness, seed_start, episodes)
    chosen = choose_teams(run_dir, team, generation, top)
    world, S, ticks = _scenario_and_teams(run_dir, cfg, chosen, scenario, ticks)
    score_fn = fitness if fitness is not None else team_scores
    genome, all_designs, variants, teams = _knockout_batch(chosen, cfg, seeds)
    E = teams.shape[0]
    layout_ids = torch.arange(episodes).repeat(E // episodes)

    _check_memory(E, S, len(chosen), episodes, world, dev)

    layouts = draw_layouts(world, S, seeds, progress)
    species = torch.tensor([int(d["species"]) for d in all_designs])
    ep = run_episodes(
        genome, species, teams, layouts, layout_ids, world, cfg, ticks, dev, score_fn, progress
    )
    cls = torch.tensor([i for i, c in enumerate(world.packages) for _ in range(c.count)])
    per_class = torch.zeros(E, len(world.packages), dtype=torch.float64)
    per_class.index_add_(1, cls, ep.delivered.double())
    out = _team_results(chosen, variants, ep.scores, ep.cost, per_class, world, episodes, S)
    if generation is not None:
        selection = f"generation {generation}"
    elif top is not None:
        selection = f"top {top}"
    else:
        selection = team
    return EvaluationResult(
        run_dir=str(run_dir),
        selection=selection,
        scenario=world.name,
        own_scenario=scenario is None,
        episodes=episodes,
        seed_start=seed_start,
        seeds=(seeds[0], seeds[-1]),
        ticks=int(ticks),
        device=str(dev),
        tick=ep.tick,
        fitness_function=("built-in" if fitness is None else f"custom: {score_fn_name(fitness)}"),
        interval=INTERVAL,
        teams=out,
    )
