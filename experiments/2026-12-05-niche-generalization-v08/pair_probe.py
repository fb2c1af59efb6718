"""What `knockout_pairs` flags: a run of the default plus `knockout_pairs=0.05` in which every
substitute pair the test finds is logged with the team's score and the relative losses of the
two single knock-outs and of the joint one.

    python pair_probe.py WORLD SEED GENERATIONS

WORLD: a built-in world or a scenario TOML. Prints the flagged pairs' count, how many have a
joint loss within 0.05 of the sum of the singles (additive: two separate jobs), the quartiles
of the joint loss, and the last 15 pairs (generation, score, single i, single j, joint); then
each demotion's species, the admission's moving average of its gated share when demoted, and
how often each species was demoted."""

from __future__ import annotations

import statistics
import sys
from dataclasses import replace

import torch

from swarmcode_torch.coevo import knockout
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.evolve import Evolution


def main() -> None:
    world, seed, gens = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    cfg = replace(
        SwarmCoDeConfig(), scenario=world, population=50, seed=seed, essential_floor=0,
        admission_basis="members", knockout_pairs=0.05, device="cpu",
    )  # fmt: skip
    real, log, gen = knockout.substitute_pairs, [], [0]

    def spy(scores, m, left, margin):
        out = real(scores, m, left, margin)
        s0 = float(scores[0])
        single = (scores[0] - scores[1 : 1 + m]) / s0
        joint = (scores[0] - scores[1 + m :]) / s0
        for (i, j), f, jl in zip(torch.combinations(torch.arange(m), 2).tolist(), out, joint):
            if f:
                log.append(
                    (gen[0], round(s0), *(round(float(v), 3) for v in (single[i], single[j], jl)))
                )
        return out

    real_demote, demoted = knockout.demote_substitutes, []

    def spy_demote(adm, res, sp, genome, ph, ctx, g):
        out = real_demote(adm, res, sp, genome, ph, ctx, g)
        if adm is not None and out is not adm:
            for who in (adm.partner & ~out.partner).nonzero().flatten().tolist():
                demoted.append((gen[0], who, round(float(adm.gated[who]), 2)))
        return out

    knockout.substitute_pairs = spy
    knockout.demote_substitutes = spy_demote
    ev = Evolution(cfg)
    for g in range(gens):
        gen[0] = g
        ev.step()
    additive = [x for x in log if x[4] <= max(x[2], 0) + max(x[3], 0) + 0.05]
    q = statistics.quantiles([x[4] for x in log], n=4) if len(log) > 1 else []
    print(f"{world} seed {seed}, {gens} generations: {len(log)} flagged pairs, {len(additive)} "
          f"additive; joint loss quartiles {[round(v, 3) for v in q]}")  # fmt: skip
    for x in log[-15:]:
        print(x)
    by = {w: sum(1 for d in demoted if d[1] == w) for w in sorted({d[1] for d in demoted})}
    gated = sorted(d[2] for d in demoted)
    print(f"{len(demoted)} demotions; demotions by species {by}; gated share of the demoted: "
          f"min {gated[0] if gated else '-'}, median "
          f"{statistics.median(gated) if gated else '-'}, max {gated[-1] if gated else '-'}")  # fmt: skip


if __name__ == "__main__":
    main()
