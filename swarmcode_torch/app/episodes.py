"""Recorded episodes of one team in one environment, and what they say: who picked up and who
delivered each package, and where two arenas of the same environment part.

`record_episode` runs a team (rows of a :class:`~swarmcode_torch.coevo.population.Population`)
through one random environment of a scenario on the CPU with the tick evolution uses there
(`sim.runtime.tick_function`: the fused C++ tick, or the Python reference tick where it cannot
be built or ``SWARMCODE_TICK=reference``), tick by tick, and keeps snapshots of the state.

Credits are derived from consecutive states, exactly, without touching the tick: a package
whose status becomes DELIVERED at tick t was delivered by the robots holding it at tick t - 1
(the tick's drop reads the holder of the state before it; a collaborative package is credited
to each of its carriers), and a package whose ``p_picked`` becomes true at tick t was picked up
by the robots holding its grips at tick t (all its grips held at once: `episode_metrics` counts
such a first lift). Summed over robots, the individual packages' credits are the episode
metrics ``delivered_individual`` and ``picked_individual``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import torch
from torch import Tensor

from ..coevo.evaluation import team_robots
from ..coevo.population import PINCHER, SUCTION, Population, from_designs
from ..sim import bt
from ..sim.layout import Layout, make_layouts
from ..sim.rollout import rollout
from ..sim.runtime import tick_function, tick_mode
from ..sim.scenario import Scenario
from ..sim.sense import sense
from ..sim.state import DELIVERED, Robots, State, WorldParams, compatible, random_keys

_EFFECTOR_NAMES = {SUCTION: "suction", PINCHER: "pincher"}

#: progress(stage, done, total), as `team_eval.ProgressFn`: stage "ticks" while recording
ProgressFn = Callable[[str, int, int], None]

#: Credit kinds: (delivered | picked) x (individual | collaborative package)
CREDIT_KINDS = ("delivered_individual", "delivered_collab", "picked_individual", "picked_collab")


# ------------------------------------------------------------------ teams from summary.json
def team_genome(designs: Sequence[dict], tag_length: int = 16) -> tuple[Population, Tensor]:
    """A Population with one row per design of a run summary, and the team's slots.

    `designs` are summary.json "designs" entries (tiers 1..3, effector by name, "bt" opcode
    list, "count" robots each). Returns the genome (tags all zero) and a ``[S]`` long tensor of
    the design row of every robot, `count` robots per design in design order.
    """
    genome, counts = from_designs(designs, tag_length)
    return genome, torch.arange(counts.numel()).repeat_interleave(counts)


# ------------------------------------------------------------------ recording
@dataclass
class Episode:
    """One recorded episode of one environment.

    `layout` and `robots` are the simulated batch of one environment (leading dimension 1);
    each snapshot is a :class:`~swarmcode_torch.sim.state.State` of that environment *without*
    the environment dimension (``pos [N, 2]``, ``p_pos [P, 2]``, ``holder [P, G]``, ...).
    `metrics` are the episode metrics of the final state, as floats.
    """

    layout: Layout
    robots: Robots
    params: WorldParams
    snapshots: list[State]
    metrics: dict[str, float]
    name: str = ""  # shown in frame titles (scenario name)
    labels: list[str] = field(default_factory=list)  # legend text per design row
    #: with record_episode(leaves=True): the leaf statuses ``[N, 14]`` the trees read at ticks
    #: 1 .. T (`sense` of the state before each tick), for `bt.trace`
    leaves: list[Tensor] = field(default_factory=list)
    #: each credit as (tick, robot, package, kind), kind an index of CREDIT_KINDS, in tick order
    credits: list[tuple[int, int, int, int]] = field(default_factory=list)
    tick: str = ""  # how the ticks ran (`sim.runtime.tick_mode`): "fused", "eager", ...

    @property
    def num_designs(self) -> int:
        return int(self.robots.program.max()) + 1 if self.robots.program.numel() else 0

    def credit_counts(self, upto: int | None = None) -> Tensor:
        """``[N, 4]`` long: each robot's credits (CREDIT_KINDS) up to tick `upto` (all)."""
        out = torch.zeros(self.robots.radius.shape[1], len(CREDIT_KINDS), dtype=torch.long)
        for t, r, _, k in self.credits:
            if upto is None or t <= upto:
                out[r, k] += 1
        return out


def _env0(state: State) -> State:
    return State(*(x.clone() if x.dim() == 0 else x[0].clone() for x in state))


def tick_credits(
    prev: State, cur: State, collab: Tensor, t: int
) -> list[tuple[int, int, int, int]]:
    """The credits of tick `t` (module docstring) from the states before and after it, of one
    environment (no environment dimension); `collab` ``[Q]`` bool."""
    out = []
    done = (cur.p_status == DELIVERED) & (prev.p_status != DELIVERED)
    first = cur.p_picked & ~prev.p_picked
    for kind, new, holding in ((0, done, prev.holding), (2, first, cur.holding)):
        if not bool(new.any()):
            continue
        hit = (holding >= 0) & new[holding.clamp_min(0)]
        for r in torch.nonzero(hit).flatten().tolist():
            q = int(holding[r])
            out.append((t, r, q, kind + int(bool(collab[q]))))
    return out


def episode_leaves(
    states: Sequence[State], layout: Layout, robots: Robots, params: WorldParams
) -> list[Tensor]:
    """The leaf statuses ``[N, 14]`` that `sense` gives on each state of one environment (no
    environment dimension): the states as one batch, in chunks that bound the memory."""
    if not states:
        return []
    compat = compatible(layout, robots, params)
    keys = random_keys(layout, robots.radius.shape[1])
    N, H = compat.shape[1:]
    chunk = max(1, (1 << 22) // max(1, N * H))
    out: list[Tensor] = []
    for a in range(0, len(states), chunk):
        part = states[a : a + chunk]
        E = len(part)
        batch = State(
            *(part[0].t if i == 0 else torch.stack([s[i] for s in part]) for i in range(14))
        )

        def grow(x: Tensor, E: int = E) -> Tensor:
            return x.expand(E, *x.shape[1:])

        lay = Layout(*(grow(x) for x in layout))
        rob = Robots(*(grow(x) for x in robots))
        leaf = sense(batch, lay, rob, grow(compat), grow(keys), params).leaf
        out.extend(leaf.unbind(0))
    return out


def record_episode(
    genome: Population,
    team: Tensor,
    scenario: Scenario,
    seed: int,
    ticks: int | None = None,
    every: int = 1,
    params: WorldParams | None = None,
    leaves: bool = False,
    step_fn: Callable | None = None,
    progress: ProgressFn | None = None,
) -> Episode:
    """Run the team (``[S]`` genome rows, -1 = empty slot) in one random environment on the CPU.

    The environment is ``make_layouts(replace(scenario, num_robots=S), 1, Generator(seed))``;
    a snapshot is kept at tick 0, every `every` ticks, and at the last tick; the credits of
    every tick are kept whatever `every` is. `leaves`: keep the leaf statuses of every tick
    too (`Episode.leaves`). `step_fn`: the tick (default the CPU's, `tick_function`).
    `progress("ticks", t, ticks)` is called as the ticks run.
    """
    ticks = scenario.episode_ticks if ticks is None else int(ticks)
    genome = genome.to("cpu")
    teams = _checked(genome, team, ticks, every)
    S = teams.shape[1]
    params = params or WorldParams.for_scenario(scenario)
    layout = make_layouts(
        dataclasses.replace(scenario, num_robots=S), 1, torch.Generator().manual_seed(int(seed))
    )
    robots = team_robots(genome, teams, scenario.hardware)  # as the evaluation builds them
    tables = bt.build_tables(genome.bt)
    compiled = False
    if step_fn is None:
        step_fn, compiled = tick_function(torch.device("cpu"), compile=False)

    snaps: list[State] = []
    every_state: list[State] = []  # with leaves: the states before ticks 1 .. T
    credits: list[tuple[int, int, int, int]] = []
    collab = layout.p_collab[0]
    last: list[State] = []
    report = max(1, ticks // 100)

    def keep(t: int, state: State) -> None:
        s = _env0(state)
        if last:
            credits.extend(tick_credits(last[0], s, collab, t))
            last[0] = s
        else:
            last.append(s)
        if t % every == 0 or t == ticks:
            snaps.append(s)
        if leaves and t < ticks:
            every_state.append(s)
        if progress is not None and (t % report == 0 or t == ticks):
            progress("ticks", t, ticks)

    with torch.no_grad():
        m = rollout(layout, robots, tables, params, ticks, step_fn=step_fn, observe=keep)
        seen = episode_leaves(every_state, layout, robots, params) if leaves else []
    metrics = {k: float(v[0]) for k, v in m.items()}

    return Episode(
        layout,
        robots,
        params,
        snaps,
        metrics,
        scenario.name,
        _labels(genome, teams),
        seen,
        credits,
        tick_mode(step_fn, compiled),
    )


def _checked(genome: Population, team: Tensor, ticks: int, every: int) -> Tensor:
    """The team as a ``[1, S]`` long tensor; ValueError for a bad team, `ticks` or `every`."""
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    if ticks < 0:
        raise ValueError(f"ticks must be >= 0, got {ticks}")
    teams = torch.as_tensor(team, dtype=torch.long).reshape(1, -1).cpu()
    if teams.shape[1] == 0:
        raise ValueError("the team has no robot slot")
    if int(teams.max()) >= genome.size:
        raise ValueError(f"team refers to row {int(teams.max())} of a genome of {genome.size}")
    return teams


def _labels(genome: Population, teams: Tensor) -> list[str]:
    """The legend text of each design row: effector, radius, robots in the team."""
    return [
        f"{_EFFECTOR_NAMES.get(int(genome.effector[r]), '?')} "
        f"r={float(genome.radius[r]):.2f} x{int((teams == r).sum())}"
        for r in range(genome.size)
    ]


# ------------------------------------------------------------------ two arenas compared
#: Two robots in the same slot of two arenas are apart once their positions differ by more
#: than this (m): far below what a frame shows, far above float rounding.
DIVERGENCE_EPS = 1e-3


def divergence(a: Episode, b: Episode, slots: Tensor, eps: float = DIVERGENCE_EPS):
    """(tick, slot) of the first snapshot at which the robot of a slot in `slots` (``[N]`` bool:
    the slots both teams share, e.g. all but the focal design's) stands more than `eps` apart
    in the two episodes, or None where they never part (or share no slot)."""
    slots = slots & a.robots.present[0] & b.robots.present[0]
    if not bool(slots.any()):
        return None
    for sa, sb in zip(a.snapshots, b.snapshots):
        d = torch.where(slots, (sa.pos - sb.pos).norm(dim=-1), 0.0)
        if bool((d > eps).any()):
            return int(sa.t), int(d.argmax())
    return None
