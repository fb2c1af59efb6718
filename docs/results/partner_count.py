"""How does the number of partner species change a team's score, in one evolved population?

    python docs/results/partner_count.py RUN_DIR [--ticks T] [--repeats R]

Loads the population of RUN_DIR's checkpoint (any device; evaluated on the CPU), and evaluates it
as `evolve` does, several times, with every individual's selectivity replaced so that exactly
its k species of nearest prototype tag are its partners (k = 1, 3, 6, 10 and all; ties in tag
distance can add more). Prints, per k, the mean number of species in the focal teams, the mean
focal team score, the mean gated fitness (what selection sees), the share of positive marginal
contributions and the mean deliveries. A first table gives the same for the population as it
evolved (its own selectivities), by the number of species in the focal team. Used in
docs/RESULTS.md ("Differences, and why") and docs/MODEL.md ("Best team of a generation").
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import torch

from swarmcode_torch.evaluation import evaluate
from swarmcode_torch.evolve import load_state_dict, make_context
from swarmcode_torch.runs import load_checkpoint, read_config
from swarmcode_torch.speciation import hamming, speciate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--ticks", type=int, default=None, help="episode length [default: the run's]")
    ap.add_argument("--repeats", type=int, default=2, help="evaluations per k (seeds 0..R-1)")
    args = ap.parse_args()
    cfg = read_config(args.run)
    ctx = make_context(replace(cfg, device="cpu", compile=False))
    ck = load_checkpoint(args.run)
    ck["rng_state"] = torch.Generator().get_state()    # a CUDA run's generator state: not used
    st = load_state_dict(ck, ctx)
    g = st.genome
    sp = speciate(g, st.species_hint, st.proto, st.proto_ids, st.next_species_id, cfg.delta)
    k_all = sp.proto_ids.numel() - 1
    dist = hamming(g.tag, g.tag[sp.proto_index]) / g.tag.shape[1]
    dist = dist.masked_fill(sp.species[:, None] == sp.proto_ids[None, :], float("inf"))
    ecfg = ctx.eval_cfg if args.ticks is None else replace(ctx.eval_cfg, ticks=args.ticks)
    print(f"{args.run.name}: generation {st.generation}, {k_all + 1} species, {ecfg.ticks} ticks")
    def scores(selectivity: torch.Tensor) -> torch.Tensor:
        """[R * P, 5]: species in the focal team, focal score, gated fitness, positive, deliveries."""
        rows = []
        for rep in range(args.repeats):
            r = evaluate(replace(g, selectivity=selectivity), sp.species, sp.proto_ids,
                         sp.proto_index, st.fitness, st.has_fitness, ctx.scenario, ecfg,
                         torch.Generator().manual_seed(rep), ctx.params)
            delivered = r.team_metrics["delivered_individual"] + r.team_metrics["delivered_collab"]
            rows.append(torch.stack([r.swarms.focal_species_count.float(), r.focal, r.fitness,
                                     (r.focal > r.baseline).float(), delivered], 1))
        return torch.cat(rows)

    head = ("species in the team | evaluations | focal score | gated fitness | positive marginal "
            "| deliveries |")
    print(f"\nAs evolved:\n| {head}\n|---|---|---|---|---|---|")
    x = scores(g.selectivity)
    for lo, hi in ((1, 2), (2, 4), (4, 7), (7, 11), (11, 10_000)):
        m = (x[:, 0] >= lo) & (x[:, 0] < hi)
        if bool(m.any()):
            v = x[m].mean(0).tolist()
            label = f"{lo}" if hi == lo + 1 else (f"{lo}+" if hi == 10_000 else f"{lo}-{hi - 1}")
            print(f"| {label} | {int(m.sum())} | {v[1]:.0f} | {v[2]:.0f} | {v[3]:.2f} | {v[4]:.1f} |")
    print(f"\nPartners set to the k nearest tags:\n| k | {head}\n|---|---|---|---|---|---|---|")
    for k in sorted({min(k, k_all) for k in (1, 3, 6, 10, k_all)}):
        v = scores(dist.sort(1).values[:, k - 1] + 1e-4).mean(0).tolist()
        label = "all" if k == k_all else str(k)
        print(f"| {label} | {v[0]:.1f} | {args.repeats * g.size} | {v[1]:.0f} | {v[2]:.0f} | "
              f"{v[3]:.2f} | {v[4]:.1f} |")


if __name__ == "__main__":
    main()
