"""Rerun one study run with its generation readout logged: per generation, the classes and
species of the best team as the run reports it (`cur`: the focal team of the highest gated
fitness), of the focal team of the highest smoothed fitness (`ema`) and of the highest ungated
focal score (`focal`), the share of all focal teams that hold a robot able to lift each class
(`share_full`, read with the simulator's lift rule to describe the run, never by evolution), and
the mean focal and gated scores of those teams and of the others. Evolution is unchanged (the
readout does not feed it): the run is the study's run of the same world, seed and arm.

    python readout_probe.py OUT.jsonl WORLD.toml evolve --scenario WORLD.toml --population 50 \
        --seed S --device cpu --logdir DIR --render-every 0 --figure-every 100000 \
        --checkpoint-every 50 --threads 1 --generations 300 [the arm's --set K=V ...]

Results: `results/readout_probe/` (train-r-08 seed 1, arms v07 and v24; PLAN.md, "v24")."""

import dataclasses
import json
import sys

import swarmcode_torch.coevo.evolve as E
from swarmcode_torch.app.cli import main as cli_main
from swarmcode_torch.app.records import team_record
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.state import WorldParams, capabilities


def main() -> None:
    out_path, scen_path = sys.argv[1], sys.argv[2]
    scen = load_scenario(scen_path)
    params = WorldParams.for_scenario(scen)
    log = open(out_path, "w")
    orig = E.read_generation
    gen = [0]

    def cover(best):
        rec = team_record(best, 0, scen)
        return sorted({c for d in rec["designs"] for c in d["capability"]}), rec["species"]

    def patched(genome, species, res, ph, fitness, n_elites):
        r = orig(genome, species, res, ph, fitness, n_elites)
        row = {"g": gen[0], "cur": cover(r.best_team)}
        for name, score in (("ema", fitness), ("focal", res.focal)):
            alt = orig(
                genome, species, dataclasses.replace(res, fitness=score), ph, fitness, n_elites
            )
            row[name] = cover(alt.best_team)
        can = capabilities(ph, scen, params)  # [P, C]
        t = res.swarms.focal_team
        full = (can[t.clamp(min=0)] & (t >= 0)[..., None]).any(1).all(1)  # [B]
        row["share_full"] = float(full.float().mean())
        for key, v in (("mean", res.focal), ("gated", res.fitness)):
            row[f"{key}_full"] = float(v[full].mean()) if full.any() else None
            row[f"{key}_part"] = float(v[~full].mean()) if (~full).any() else None
        log.write(json.dumps(row) + "\n")
        log.flush()
        gen[0] += 1
        return r

    E.read_generation = patched
    sys.argv = ["swarmcode-torch", *sys.argv[3:]]
    cli_main()


if __name__ == "__main__":
    main()
