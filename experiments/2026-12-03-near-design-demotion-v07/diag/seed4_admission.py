"""Four-niche seed 4 with the 0.6 default: per generation, every species' size, partner flag,
gated share (moving average) and the package classes its prototype can lift."""
import sys
import torch
import swarmcode_torch as sc
from swarmcode_torch.app import records
from swarmcode_torch.app.api import start_evolution, make_config
from swarmcode_torch.app.records import _capability_lists
from swarmcode_torch.coevo.fitness import beats_baseline
from swarmcode_torch.coevo.population import genome_phenotype

cfg = make_config(scenario="four-niche", seed=4, population=50, swarm_size=20, device="cpu",
                  generations=int(sys.argv[1]) if len(sys.argv) > 1 else 60)
ev, _ = start_evolution(cfg)
scen = ev.ctx.scenario
log = []

def after(e):
    sp = e.speciation
    ph = genome_phenotype(e.state.genome.index(sp.proto_index), scen.hardware)
    caps = _capability_lists(ph, scen)
    adm = e.next_state.admission
    ids, sizes = torch.unique(sp.species, return_counts=True)
    size = dict(zip(ids.tolist(), sizes.tolist()))
    gated = ~beats_baseline(e.evaluation.focal, e.evaluation.baseline)
    rows = []
    for k, pid in enumerate(sp.proto_ids.tolist()):
        if pid not in size:
            continue
        m = sp.species == pid
        rows.append(f"{pid}:{size[pid]}{'P' if adm.partner[pid] else 'p'}"
                    f"{''.join(map(str, caps[k]))}/g{gated[m].float().mean():.1f}"
                    f"/a{adm.gated[pid]:.2f}")
    print(e.generation, " ".join(rows), flush=True)

ev.hooks.after_reproduction.append(after)
while not ev.done:
    r = records.step(ev)
    print("   best team species", r.team["species"] if r.team else None, "niches", r.team.get("niches") if r.team else None, flush=True)
