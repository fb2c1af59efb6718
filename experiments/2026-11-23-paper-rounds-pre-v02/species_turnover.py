"""Where do a run's species come from, how long do they live, and which of them are in the teams?

    python experiments/2026-11-23-paper-rounds-pre-v02/species_turnover.py RUN_DIR [RUN_DIR ...]
    python experiments/2026-11-23-paper-rounds-pre-v02/species_turnover.py --founders SCENARIO [--generations N] [--seed S]
                                            [--ticks T] [--set KEY=VALUE ...]

The first form reads each run's checkpoint (its per-generation species history) and prints:
the number of species ever founded and their median lifetime; over the last 100 generations,
the median number of species in the population, and how many of them are young (< 20
generations) and old (>= 50); the mean number of species in the best team by age (0, 1-4,
5-19, 20-49, 50+ generations); and the pairs of final prototypes that lie within the speciation
threshold of each other (species that would be one if founded today).

The second form runs an evolution (population 50, swarm 20, CPU, compiled tick) and records
every species founding: the distance of the founder to the prototype of its parent's species,
by term (tag, hardware, BT, tool, size), and its cause: an effector flip, a tier change, or
else the largest drift term. It prints the founding rate and causes after generation 50 and the
median species counts of the last 50 generations. Used in docs/RESULTS.md ("Why the teams held
so many species").
"""

from __future__ import annotations

import argparse
import collections
import statistics
from pathlib import Path

import swarmcode_torch.coevo.evolve as evolve
from swarmcode_torch.app.settings import parse_settings
from swarmcode_torch.coevo.config import SwarmCoDeConfig, with_overrides
from swarmcode_torch.coevo.population import Population
from swarmcode_torch.app.runs import load_checkpoint, read_config
from swarmcode_torch.coevo.speciation import distance, distance_terms

AGE_BUCKETS = ((0, 1, "0"), (1, 5, "1-4"), (5, 20, "5-19"), (20, 50, "20-49"), (50, 10**9, "50+"))


def history_report(run: Path) -> None:
    ck = load_checkpoint(run)
    hist = ck["history"]
    first, last = {}, {}
    for rec in hist:
        for s in rec["population"]:
            first.setdefault(int(s), rec["generation"])
            last[int(s)] = rec["generation"]
    life = [last[s] - first[s] + 1 for s in first]
    window = hist[-100:]
    pop, young, old = [], [], []
    team_age = collections.Counter()
    for rec in window:
        g = rec["generation"]
        ages = [g - first[int(s)] for s in rec["population"]]
        pop.append(len(ages))
        young.append(sum(a < 20 for a in ages))
        old.append(sum(a >= 50 for a in ages))
        for s in rec["team"]:
            a = g - first[int(s)]
            team_age[next(name for lo, hi, name in AGE_BUCKETS if lo <= a < hi)] += 1
    med = statistics.median
    print(f"{run.name}: {len(first)} species founded in {len(hist)} generations, median lifetime "
          f"{med(life):g}; last {len(window)} generations: {med(pop):g} species in the population, "
          f"{med(young):g} younger than 20 generations, {med(old):g} of 50 or more")
    print("  species in the best team by age (mean per generation): " + ", ".join(
        f"{name}: {team_age[name] / len(window):.2f}" for _, _, name in AGE_BUCKETS))
    proto, ids = Population.from_state_dict(ck["proto"]), ck["proto_ids"].tolist()
    delta = read_config(run).delta
    d = distance(proto, proto)
    close = [f"{ids[i]}/{ids[j]} ({'SP'[int(proto.effector[i])]} {float(proto.radius[i]):.2f} m, "
             f"{'SP'[int(proto.effector[j])]} {float(proto.radius[j]):.2f} m): D = {float(d[i, j]):.2f}"
             for i in range(len(ids)) for j in range(i + 1, len(ids)) if d[i, j] <= delta]
    print(f"  final prototypes: {len(ids)}; pairs within delta = {delta:g}: "
          + ("; ".join(close) if close else "none"))


def terms(a: Population, b: Population) -> dict:
    """The weighted terms of D between single genomes a and b, and the number of differing tiers."""
    out = {k: float(v) for k, v in distance_terms(a, b).items()}
    out["tiers"] = int((a.chassis != b.chassis).sum() + (a.battery != b.battery).sum()
                       + (a.motor != b.motor).sum())
    return out


def cause(rec: dict) -> str:
    if "tool" not in rec:
        return "parent's species gone"
    if rec["tool"] > 0:
        return "effector flip"
    if rec["tiers"] > 0:
        return "tier change"
    return "drift: " + max(("tag", "hw", "bt", "size"), key=lambda k: rec[k])


def founders_report(args) -> None:
    log: list[dict] = []

    def recording_speciate(e: evolve.AfterSpeciation) -> None:
        genome, hint, next_id, sp = (e.state.genome, e.state.species_hint,
                                     e.state.next_species_id, e.speciation)
        ids = sp.proto_ids.tolist()
        n_new = sp.next_species_id - next_id
        for row in sp.proto_index[len(ids) - n_new:].tolist():
            rec = {"generation": e.generation}
            parent_species = int(hint[row])
            if parent_species in ids:
                proto_row = int(sp.proto_index[ids.index(parent_species)])
                rec.update(terms(genome.index(slice(row, row + 1)),
                                 genome.index(slice(proto_row, proto_row + 1))))
            log.append(rec)

    cfg = with_overrides(
        SwarmCoDeConfig(scenario=args.founders, population=50, swarm_size=20,
                        generations=args.generations, seed=args.seed, device="cpu",
                        compile=True, ticks=args.ticks),
        **parse_settings(args.settings or []))
    ev = evolve.Evolution(cfg)
    ev.hooks.after_speciation.append(recording_speciate)
    counts = []
    while not ev.done:
        m = ev.step()
        counts.append((m.num_species, int(m.best_team.rows.numel())))
    late = [r for r in log if r["generation"] >= 50]
    n_late = max(args.generations - 50, 1)
    print(f"{args.founders}, seed {args.seed}, {args.generations} generations, {ev.cfg.ticks} ticks: "
          f"{len(log)} species founded; after generation 50: {len(late)} ({len(late) / n_late:.2f} "
          f"per generation)")
    for name, n in collections.Counter(cause(r) for r in late).most_common():
        print(f"  {name}: {n} ({100 * n / max(len(late), 1):.0f} %)")
    with_terms = [r for r in late if "tool" in r]
    print("  mean distance term of a founder to its parent species' prototype: " + ", ".join(
        f"{k} {sum(r[k] for r in with_terms) / max(len(with_terms), 1):.3f}"
        for k in ("tag", "hw", "bt", "tool", "size")))
    tail = counts[-50:]
    print(f"  last {len(tail)} generations, median species: population "
          f"{statistics.median(c[0] for c in tail):g}, best team {statistics.median(c[1] for c in tail):g}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", type=Path, nargs="*")
    ap.add_argument("--founders", metavar="SCENARIO", help="run an instrumented evolution")
    ap.add_argument("--generations", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--ticks", type=int, default=None, help="episode length [scenario's]")
    ap.add_argument("--set", dest="settings", action="append", metavar="KEY=VALUE")
    args = ap.parse_args()
    if args.founders is None and not args.runs:
        ap.error("give run directories, or --founders SCENARIO")
    for run in args.runs:
        history_report(run)
    if args.founders is not None:
        founders_report(args)


if __name__ == "__main__":
    main()
