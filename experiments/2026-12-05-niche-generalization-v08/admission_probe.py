"""Rerun one study run with the partner admission logged: per generation, each species' size,
whether it is a partner before and after the generation's admission update, its gated-share
moving average, and which species the previous best team forces as partners
(`team_partners`), with the classes and species of the best team the run reports (read with the
simulator's lift rule to describe the run, never by evolution). Evolution is unchanged: the run
is the study's run of the same world, seed and arm.

    python admission_probe.py OUT.jsonl WORLD.toml evolve --scenario WORLD.toml --population 50 \
        --seed S --device cpu --logdir DIR --render-every 0 --figure-every 100000 \
        --checkpoint-every 50 --threads 1 --generations 300 [the arm's --set K=V ...]

Results: `results/admission_probe/` (gzipped JSON lines: v27 on train-r-13 seeds 0 and 2,
v29 on train-r-13 seed 2, train-03 seed 0 and train-r-08 seed 1; PLAN.md, "v29")."""

import json
import sys

import swarmcode_torch.coevo.admission as A
import swarmcode_torch.coevo.evolve as E
import swarmcode_torch.coevo.partners as P
from swarmcode_torch.app.cli import main as cli_main
from swarmcode_torch.app.records import team_record
from swarmcode_torch.sim.scenario import load_scenario


def main() -> None:
    out_path, scen_path = sys.argv[1], sys.argv[2]
    scen = load_scenario(scen_path)
    log = open(out_path, "w")
    row: dict = {"g": 0}
    orig_update, orig_mask, orig_read = A.update, P.team_partner_mask, E.read_generation

    def update(adm, species, proto_ids, gated, nearest, *a, **k):
        out = orig_update(adm, species, proto_ids, gated, nearest, *a, **k)
        ids = proto_ids.tolist()
        size = [(species == i).sum().item() for i in ids]
        share = [
            round(gated[species == i].float().mean().item(), 2) if n else None
            for i, n in zip(ids, size)
        ]
        row["species"] = {
            str(i): {
                "n": n,
                "share": s,
                "avg": round(out.gated[i].item(), 2),
                "before": bool(adm.partner[i]),
                "after": bool(out.partner[i]),
                "nearest": ids[j] if j >= 0 else None,
            }
            for i, n, s, j in zip(ids, size, share, nearest.tolist())
        }
        return out

    def mask(history, proto_ids):
        m = orig_mask(history, proto_ids)
        row["forced"] = [] if m is None else proto_ids[m].tolist()
        return m

    def read(*a, **k):
        r = orig_read(*a, **k)
        rec = team_record(r.best_team, 0, scen)
        row["best"] = sorted({c for d in rec["designs"] for c in d["capability"]})
        row["team"] = {str(d["species"]): d["count"] for d in rec["designs"]}
        log.write(json.dumps(row) + "\n")
        log.flush()
        row.clear()
        row["g"] = r_gen[0] = r_gen[0] + 1
        return r

    r_gen = [0]
    A.update, P.team_partner_mask, E.read_generation = update, mask, read
    sys.argv = ["swarmcode-torch", *sys.argv[3:]]
    cli_main()


if __name__ == "__main__":
    main()
