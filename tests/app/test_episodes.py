"""Recorded episodes (`app.episodes`): the replay's rollout on the CPU's tick against the Python
reference tick, the credits of each pick-up and delivery, and where two arenas part."""

import pytest
import torch
from replaykit import DESIGNS

from swarmcode_torch.app.episodes import (
    CREDIT_KINDS,
    DIVERGENCE_EPS,
    divergence,
    episode_leaves,
    record_episode,
    team_genome,
)
from swarmcode_torch.sim.fused import FusedTicks
from swarmcode_torch.sim.rollout import rollout
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.sense import sense
from swarmcode_torch.sim.state import DELIVERED, State, TickInputs, compatible, random_keys
from swarmcode_torch.sim.step import step

needs_fused = pytest.mark.skipif(
    not FusedTicks().ready(warn=False), reason="the fused C++ tick cannot be built here"
)


def _batch(s: State) -> State:
    return State(*(x if x.dim() == 0 else x[None] for x in s))


def _close(a: State, b: State, what: str) -> None:
    """As tests/sim/test_fused.py compares the two ticks: discrete fields equal, floats to
    relative and absolute 1e-4 (the contact solver sums its pairs in another order)."""
    for name, x, y in zip(a._fields, a, b):
        if x.dtype.is_floating_point:
            assert torch.allclose(x, y, rtol=1e-4, atol=1e-4), (what, name, (x - y).abs().max())
        else:
            assert torch.equal(x, y), (what, name)


@pytest.fixture(scope="module")
def budget_episode():
    genome, team = team_genome(DESIGNS)
    return record_episode(genome, team, load_scenario("budget"), seed=3, ticks=400, leaves=True)


@needs_fused
def test_the_replay_records_the_fused_tick_and_every_tick_agrees_with_the_reference():
    genome, team = team_genome(DESIGNS[:2])
    scenario = load_scenario("one-niche")
    ep = record_episode(genome, team, scenario, seed=2, ticks=120)
    assert ep.tick == "fused" and len(ep.snapshots) == 121
    # each recorded tick is the reference tick of the recorded state before it
    lay, rob, p = ep.layout, ep.robots, ep.params
    from swarmcode_torch.sim import bt

    inputs = TickInputs(
        lay,
        rob,
        compatible(lay, rob, p),
        random_keys(lay, rob.radius.shape[1]),
        bt.build_tables(genome.bt),
    )
    for t in range(1, len(ep.snapshots)):
        ref = step(_batch(ep.snapshots[t - 1]), *inputs, p)
        _close(_batch(ep.snapshots[t]), ref, f"tick {t}")
    # and over a short episode the whole recorded trajectory is the reference's
    ref_ep = record_episode(genome, team, scenario, seed=2, ticks=30, step_fn=step)
    assert ref_ep.tick == "eager"
    for a, b in zip(ep.snapshots[:31], ref_ep.snapshots):
        _close(a, b, f"tick {int(a.t)}")
    # the last recorded state is what the evaluation's many-ticks-in-one-call run reaches
    m, final = rollout(lay, rob, inputs.tables, p, 120, step_fn=FusedTicks(), return_state=True)
    for name, x, y in zip(final._fields, _batch(ep.snapshots[-1]), final):
        assert torch.equal(x, y), name
    assert ep.metrics == {k: float(v[0]) for k, v in m.items()}


def test_the_reference_tick_is_recorded_where_it_is_chosen(monkeypatch):
    monkeypatch.setenv("SWARMCODE_TICK", "reference")
    genome, team = team_genome(DESIGNS[:1])
    ep = record_episode(genome, team, load_scenario("one-niche"), seed=0, ticks=5)
    assert ep.tick == "eager"


def test_the_leaves_are_those_sense_gives_on_each_state_before_a_tick(budget_episode):
    ep = budget_episode
    assert len(ep.leaves) == len(ep.snapshots) - 1
    compat = compatible(ep.layout, ep.robots, ep.params)
    keys = random_keys(ep.layout, ep.robots.radius.shape[1])
    for t in (0, 1, 57, 200, len(ep.leaves) - 1):
        s = _batch(ep.snapshots[t])
        want = sense(s, ep.layout, ep.robots, compat, keys, ep.params).leaf[0]
        assert torch.equal(ep.leaves[t], want), t
    # in chunks as in one batch
    some = ep.snapshots[:9]
    assert all(
        torch.equal(a, b)
        for a, b in zip(episode_leaves(some, ep.layout, ep.robots, ep.params), ep.leaves[:9])
    )


def test_credits_sum_to_the_episode_metrics_and_name_the_carriers(budget_episode):
    ep = budget_episode
    m = ep.metrics
    assert m["delivered_individual"] > 0 and m["picked_collab"] > 0  # a meaningful episode
    counts = ep.credit_counts()
    kinds = dict(zip(CREDIT_KINDS, counts.sum(0).tolist()))
    # an individual package has one carrier: its credits are the team's counts
    assert kinds["delivered_individual"] == m["delivered_individual"]
    assert kinds["picked_individual"] == m["picked_individual"]
    # a collaborative package counts once for the team and once for each of its carriers
    for kind in ("delivered_collab", "picked_collab"):
        k = CREDIT_KINDS.index(kind)
        packages = {q for _, _, q, kk in ep.credits if kk == k}
        assert len(packages) == m[kind]
        assert kinds[kind] >= len(packages)
    snaps = ep.snapshots  # every=1: snapshot t is the state after tick t
    seen = set()
    for t, r, q, k in ep.credits:
        assert (q, k) not in seen or k in (1, 3)  # a package is delivered / first lifted once
        seen.add((q, k))
        if k < 2:  # the robot held it the tick before, and it was delivered at this tick
            assert int(snaps[t - 1].holding[r]) == q
            assert int(snaps[t].p_status[q]) == DELIVERED != int(snaps[t - 1].p_status[q])
        else:  # it holds it as it is first lifted
            assert int(snaps[t].holding[r]) == q
            assert bool(snaps[t].p_picked[q]) and not bool(snaps[t - 1].p_picked[q])
    assert [c[0] for c in ep.credits] == sorted(c[0] for c in ep.credits)
    # the credits up to a tick count only what happened by then
    t_mid = ep.credits[len(ep.credits) // 2][0]
    assert int(ep.credit_counts(t_mid).sum()) == sum(c[0] <= t_mid for c in ep.credits)


def test_credits_do_not_depend_on_the_snapshots_kept(budget_episode):
    genome, team = team_genome(DESIGNS)
    sparse = record_episode(genome, team, load_scenario("budget"), seed=3, ticks=400, every=7)
    assert len(sparse.snapshots) < len(budget_episode.snapshots)
    assert sparse.credits == budget_episode.credits


def test_the_arenas_part_at_the_first_tick_a_shared_robot_stands_apart():
    genome, team = team_genome(DESIGNS)
    scenario = load_scenario("budget")
    other = team.clone()
    other[team == 0] = 1  # design 0's slots refilled by design 1, as a baseline team is
    a = record_episode(genome, team, scenario, seed=1, ticks=300)
    b = record_episode(genome, other, scenario, seed=1, ticks=300)
    shared = team == other
    got = divergence(a, b, shared)
    assert got is not None
    t, slot = got
    assert bool(shared[slot])
    gap = [
        torch.where(shared, (x.pos - y.pos).norm(dim=-1), 0.0)
        for x, y in zip(a.snapshots, b.snapshots)
    ]
    assert all(float(g.max()) <= DIVERGENCE_EPS for g in gap[:t])
    assert float(gap[t][slot]) > DIVERGENCE_EPS and int(a.snapshots[t].t) == t
    # the focal's own slots differ from the first tick on: they do not count
    assert float((a.snapshots[1].pos - b.snapshots[1].pos).norm(dim=-1).max()) > 0
    assert divergence(a, a, shared) is None  # the same team never parts from itself
    assert divergence(a, b, torch.zeros_like(shared)) is None  # no shared slot
