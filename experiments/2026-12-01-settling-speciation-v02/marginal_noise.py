"""How noisy a focal's marginal contribution is: evaluate one population twice, with two random
streams, and compare each individual's relative marginal (F_focal - F_baseline) / |F_baseline|.

    python experiments/2026-12-01-settling-speciation-v02/marginal_noise.py CHECKPOINT [--json OUT]

CHECKPOINT is a run's checkpoint.pt or a snapshot of it (snap_100.pt ...); the population is
speciated as the next generation would be and evaluated with the run's saved config (trials,
ticks, swarm size) under seeds 1 and 2. Prints the quantiles of the relative marginal of the
first evaluation, the shares of individuals at or below 0, -5 % and -10 %, and the standard
deviation of one evaluation's relative marginal (std of the difference of the two / sqrt 2).
Used in docs/RESULTS.md ("How a niche is lost") to size `gate_margin`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import torch

from swarmcode_torch.app.runs import config_from_dict, read_checkpoint
from swarmcode_torch.coevo import evolve as E


def relative_marginals(checkpoint: Path, seeds: tuple[int, ...] = (1, 2)) -> list[torch.Tensor]:
    d = read_checkpoint(checkpoint)
    cfg = config_from_dict(d["config"], str(checkpoint))
    ev = E.Evolution.from_checkpoint(d, dataclasses.replace(cfg, generations=d["generation"] + 1))
    st, ctx = ev.state, ev.ctx
    sp = E.speciate(st.genome, st.species_hint, st.proto, st.proto_ids, st.next_species_id,
                    ctx.speciation.delta, w=ctx.speciation.weights)
    out = []
    for seed in seeds:
        g = torch.Generator(device=ctx.device).manual_seed(seed)
        r = E.evaluate(st.genome, sp.species, sp.proto_ids, sp.proto_index, st.fitness,
                       st.has_fitness, ctx.scenario, ctx.eval_cfg, g, ctx.params, ctx.step_fn,
                       evaluator=ctx.evaluator, score_fn=ctx.score_fn)
        out.append(((r.focal - r.baseline) / r.baseline.abs().clamp_min(1e-6)).double().cpu())
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("checkpoint", type=Path)
    ap.add_argument("--json", help="write the numbers here")
    args = ap.parse_args()
    torch.set_num_threads(1)
    a, b = relative_marginals(args.checkpoint)
    q = [0.1, 0.25, 0.5, 0.75, 0.9]
    res = {"checkpoint": str(args.checkpoint), "individuals": a.numel(),
           "quantiles": dict(zip(map(str, q), a.quantile(torch.tensor(q, dtype=a.dtype)).tolist())),
           "share_le_0": float((a <= 0).double().mean()),
           "share_le_-0.05": float((a <= -0.05).double().mean()),
           "share_le_-0.1": float((a <= -0.1).double().mean()),
           "std_one_evaluation": float((a - b).std() / 2 ** 0.5)}
    print(json.dumps(res, indent=1))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=1)


if __name__ == "__main__":
    main()
