"""How does the number of partner species change a team's score, in one evolved population?

    python experiments/2026-11-23-paper-rounds-pre-v02/partner_count.py RUN_DIR [--ticks T] [--repeats R]

Loads the population of RUN_DIR's checkpoint (any device; evaluated on the CPU), and evaluates it
as `evolve` does, several times, with every individual's selectivity replaced so that exactly
its k species of nearest prototype tag are its partners (k = 1, 3, 6, 10 and all; ties in tag
distance can add more). Prints, per k, the mean number of species in the focal teams, the mean
focal team score, the mean gated fitness (what selection sees), the share of positive marginal
contributions and the mean deliveries. A first table gives the same for the population as it
evolved (its own selectivities), by the number of species in the focal team. A last row, "one
per niche", gives every individual as partners the largest species of each niche it does not
cover itself, where a niche is a class of individual packages (effector and radius band) of the
scenario: the team a perfect partner choice would make. Used in docs/RESULTS.md ("Differences,
and why") and docs/MODEL.md ("Best team of a generation").
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import torch

from swarmcode_torch.coevo import evaluation
from swarmcode_torch.coevo.evolve import load_state_dict, make_context
from swarmcode_torch.app.runs import load_checkpoint, read_config
from swarmcode_torch.coevo.speciation import hamming, speciate


def niche_partners(genome, species, proto_ids, proto_index, scenario, elite_rows_of) -> torch.Tensor:
    """[P, K] partner rows: for each niche an individual does not cover, one elite of the largest
    species whose prototype covers it (a niche: an individual package class's effector and radius
    band); -1 elsewhere."""
    classes = [c for c in scenario.packages if c.kind == "individual"]
    def covers(rows):
        return torch.stack([(genome.effector[rows] == c.grips[0]) &
                            (genome.radius[rows] >= c.radius_band[0]) &
                            (genome.radius[rows] <= c.radius_band[1]) for c in classes], 1)
    p, k = genome.size, proto_ids.numel()
    own, proto = covers(torch.arange(p)), covers(proto_index)             # [P, C], [K, C]
    sizes = (species[:, None] == proto_ids[None, :]).sum(0)               # [K]
    out = torch.full((p, k), -1, dtype=torch.long)
    for c in range(len(classes)):
        if bool(proto[:, c].any()):
            best = int(torch.where(proto[:, c], sizes, torch.full_like(sizes, -1)).argmax())
            need = ~own[:, c] & (species != proto_ids[best])
            out[need, best] = elite_rows_of(best)[need]
    return out


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
            gs = replace(g, selectivity=selectivity)
            plan = evaluation.plan_evaluation(gs, sp.species, sp.proto_ids, sp.proto_index,
                                              st.fitness, st.has_fitness, ctx.scenario, ecfg,
                                              torch.Generator().manual_seed(rep))
            r = evaluation.evaluate(plan, gs, ctx.scenario, ecfg, ctx.params)
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
    def row(label: str, x: torch.Tensor) -> None:
        v = x.mean(0).tolist()
        print(f"| {label} | {v[0]:.1f} | {args.repeats * g.size} | {v[1]:.0f} | {v[2]:.0f} | "
              f"{v[3]:.2f} | {v[4]:.1f} |")

    for k in sorted({min(k, k_all) for k in (1, 3, 6, 10, k_all)}):
        row("all" if k == k_all else str(k), scores(dist.sort(1).values[:, k - 1] + 1e-4))

    real = evaluation.choose_partners

    def one_per_niche(tag, selectivity, species, proto_ids, proto_tag, elite_index, generator,
                      allowed=None):
        every = real(tag, torch.full_like(selectivity, 2.0), species, proto_ids, proto_tag,
                     elite_index, generator, allowed)            # one random elite per species
        return niche_partners(g, species, proto_ids, sp.proto_index, ctx.scenario,
                              lambda kk: every[:, kk])

    evaluation.choose_partners = one_per_niche
    try:
        row("one per niche", scores(g.selectivity))
    finally:
        evaluation.choose_partners = real


if __name__ == "__main__":
    main()
