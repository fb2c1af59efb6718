# Usage: python experiments/2026-11-23-paper-rounds-pre-v02/episode_calibration.py   (reads experiments/2026-11-23-paper-rounds-pre-v02/*/summary.json; CPU, about a minute)
"""Deliveries of each run's best team (from experiments/2026-11-23-paper-rounds-pre-v02 summaries) over 48 fresh environments,
at several episode lengths: where do good teams sit against the paper's 4-12 range?"""
import json, glob, torch
from dataclasses import replace
from swarmcode_torch.sim import bt
from swarmcode_torch.app.render import team_genome
from swarmcode_torch.coevo.evaluation import simulate_teams
from swarmcode_torch.sim.layout import make_layouts
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.state import WorldParams
torch.set_num_threads(2)
E = 48
for path in sorted(glob.glob("experiments/2026-11-23-paper-rounds-pre-v02/first-round-h100/niche/*-seed0/summary.json")) + ["experiments/2026-11-23-paper-rounds-pre-v02/first-round-h100/budget_sweep/budget-4000_seed-0/summary.json"]:
    s = json.load(open(path))
    scen = load_scenario(s["scenario"])
    genome, team = team_genome(s["designs"])
    S = team.numel()
    g = torch.Generator().manual_seed(123)
    layouts = make_layouts(replace(scen, num_robots=S), E, g, torch.device("cpu"))
    tables = bt.build_tables(genome.bt)
    params = WorldParams.for_scenario(scen)
    out = []
    for ticks in (120, 160, 200, 250):
        m = simulate_teams(team.expand(E, S), genome, tables, torch.arange(E), layouts, params, ticks)
        d = m["delivered_individual"] + m["delivered_collab"]
        out.append(f"{ticks}: {d.mean():.1f}±{d.std():.1f}")
    n_pk = sum(c.count for c in scen.packages)
    print(f"{s['scenario']:10s} ({len(s['designs'])} designs, {n_pk} packages)  " + "  ".join(out), flush=True)
