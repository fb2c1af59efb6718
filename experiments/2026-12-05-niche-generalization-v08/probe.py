"""Probe of a run's first generations: every species' members as focal individuals (size,
design, mean fitness, focal score, marginal contribution, share beating the baseline, slots
their design fills), one line a generation.

    python experiments/2026-12-05-niche-generalization-v08/probe.py WORLD.toml SEED GENERATIONS \
        [setting=value ...]

Runs the study's v07 arm (the 0.7 default) plus the given settings, population 50, 20 robots.
"""

import sys, torch
from dataclasses import replace
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.evolve import Evolution
from swarmcode_torch.coevo.hooks import Hooks
world, seed, gens = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
extra = dict(a.split("=") for a in sys.argv[4:])
cfg = SwarmCoDeConfig(scenario=world, population=50, seed=seed)
cfg = replace(cfg, swarm_size=20, essential_floor=0, admission_basis="members", **{k: type(getattr(cfg,k))(v) for k,v in extra.items()})
def after(ev):
    sp = ev.speciation.species; g = ev.state.genome; r = ev.evaluation
    fs = r.focal_slot if hasattr(r,'focal_slot') else None
    nslots = r.swarms.focal_slot.sum(1).float()
    rows = []
    for s in sp.unique().tolist():
        m = sp == s
        rows.append((s, int(m.sum()), "sp" if int(g.effector[m].float().mean().round())==0 else "pi", round(float(g.radius[m].float().mean()),2),
            round(float(ev.fitness[m].mean())), round(float(r.focal[m].mean())), round(float((r.focal[m]-r.baseline[m]).mean())), round(float((r.focal[m]>r.baseline[m]).float().mean()),2), round(float(nslots[m].mean()),1)))
    rows.sort(key=lambda x: -x[1])
    print(ev.generation, " | ".join(f"{s}:{n} {e}{rad} f{fit} foc{foc} marg{mg} win{w} slots{ns}" for s,n,e,rad,fit,foc,mg,w,ns in rows if n>=2), flush=True)
hooks = Hooks(after_evaluation=[after])
ev = Evolution(cfg); ev.hooks = hooks
for _ in range(gens): ev.step()
