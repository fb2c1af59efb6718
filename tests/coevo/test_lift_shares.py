"""The generator's `lift_shares` measures what a run's first generation draws: the share of
`Population.random` genomes whose robots lift each class's heaviest package (sim.state's lift
rule), within sampling error."""

from __future__ import annotations

import math
from dataclasses import replace

import torch

from swarmcode_torch.coevo.population import Population, genome_phenotype
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.state import WorldParams, capabilities
from swarmcode_torch.sim.worlds import generate_world, lift_shares


def _generation_zero_shares(scenario, n: int) -> list[float]:
    ph = genome_phenotype(Population.random(n, 8, 4, torch.Generator().manual_seed(3)))
    heavy = replace(
        scenario, packages=tuple(replace(c, mass=(c.mass[1], c.mass[1])) for c in scenario.packages)
    )
    return capabilities(ph, heavy, WorldParams.for_scenario(scenario)).float().mean(0).tolist()


def test_lift_shares_agree_with_the_first_generation_draws():
    n = 40_000
    for scenario in (
        load_scenario("four-niche"),
        generate_world(0, niches=3, bands="overlapping", mass=(2.0, 120.0)).scenario,
    ):
        ours = lift_shares(scenario, designs=n)
        ref = _generation_zero_shares(scenario, n)
        assert len(ours) == len(scenario.packages)
        for a, b in zip(ours, ref):
            p = max((a + b) / 2, 1 / n)
            # two independent samples of n: 5 standard errors of their difference
            assert abs(a - b) <= 5 * math.sqrt(2 * p * (1 - p) / n), (scenario.name, a, b)
    # the overlapping world holds a needle (a class fewer than 1 % of designs lift)
    assert min(ours) < 0.01 and min(ref) < 0.01


def test_a_class_no_robot_lifts_has_no_share_and_the_shares_are_fixed():
    s = load_scenario("one-niche")
    heavy = replace(s, packages=(replace(s.packages[0], mass=(300.0, 300.0)),))
    assert lift_shares(heavy) == [0.0]
    assert lift_shares(s) == lift_shares(s)  # a generator of its own: the same every call
    assert 0.0 < lift_shares(s)[0] <= 0.5 + 1e-9  # one effector: at most half the designs
