"""Hand-built single-environment worlds for exact rule and physics tests."""

from __future__ import annotations

import torch

from swarmcode_torch.sim import bt
from swarmcode_torch.sim.hardware import R_MAX, R_MIN, phenotype
from swarmcode_torch.sim.layout import Layout, make_layouts
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.state import Robots, WorldParams

PROGRAMS = ["forage", "forage_random", "collaborative", "cautious"]


def robot(pos, radius=0.3, effector=1, tiers=(1, 1, 2), torque=0.8, battery=0.7, program="forage"):
    return dict(
        pos=pos,
        radius=radius,
        effector=effector,
        tiers=tiers,
        torque=torque,
        battery=battery,
        program=program,
    )


def package(pos, mass=5.0, grips=(1,), band=(0.0, 10.0), size=None):
    collab = len(grips) > 1
    return dict(
        pos=pos,
        mass=mass,
        grips=grips,
        band=band,
        size=size if size is not None else (0.5 if collab else 0.2),
        collab=collab,
    )


def build(
    robots: list[dict],
    packages: list[dict],
    obstacles=(),
    arena=10.0,
    base_radius=1.0,
    seed=0,
    **params,
):
    """(layout, robots, tables, params) of one environment with exactly these contents."""
    G = max(len(p["grips"]) for p in packages)
    P, N = len(packages), len(robots)
    g_eff = torch.full((1, P, G), -1, dtype=torch.long)
    g_off = torch.zeros(1, P, G, 2)
    for i, p in enumerate(packages):
        k = len(p["grips"])
        g_eff[0, i, :k] = torch.tensor(p["grips"])
        if p["collab"]:
            a = torch.arange(k) * (2 * torch.pi / k)
            g_off[0, i, :k] = (p["size"] + 0.1) * torch.stack([a.cos(), a.sin()], -1)
    O = len(obstacles)
    layout = Layout(
        p_present=torch.ones(1, P, dtype=torch.bool),
        p_pos=torch.tensor([[p["pos"] for p in packages]], dtype=torch.float),
        p_mass=torch.tensor([[p["mass"] for p in packages]], dtype=torch.float),
        p_band=torch.tensor([[p["band"] for p in packages]], dtype=torch.float),
        p_size=torch.tensor([[p["size"] for p in packages]], dtype=torch.float),
        p_collab=torch.tensor([[p["collab"] for p in packages]]),
        g_effector=g_eff,
        g_offset=g_off,
        o_pos=torch.tensor([[o[:2] for o in obstacles]], dtype=torch.float).reshape(1, O, 2),
        o_radius=torch.tensor([[o[2] for o in obstacles]], dtype=torch.float).reshape(1, O),
        o_present=torch.ones(1, O, dtype=torch.bool),
        start=torch.tensor([[r["pos"] for r in robots]], dtype=torch.float),
        seed=torch.tensor([seed]),
    )
    f = lambda k: torch.tensor([[r[k] for r in robots]])  # noqa: E731
    tiers = torch.tensor([[r["tiers"] for r in robots]])
    ph = phenotype(
        f("radius").float(),
        tiers[..., 0],
        tiers[..., 1],
        tiers[..., 2],
        f("torque").float(),
        f("battery").float(),
        f("effector"),
    )
    prog = torch.tensor([[PROGRAMS.index(r["program"]) for r in robots]])
    rob = Robots.from_phenotype(ph, torch.ones(1, N, dtype=torch.bool), prog)
    tables = bt.build_tables(torch.stack([bt.template_tensor(n, 32) for n in PROGRAMS]))
    return layout, rob, tables, WorldParams(arena=arena, base_radius=base_radius, **params)


def random_world(name, E=3, seed=0, n_programs=12, device="cpu"):
    """(scenario, layout, robots, tables, params): E random environments of a built-in scenario
    with random hardware and a mix of the templates and random programs (drawn on the CPU)."""
    s = load_scenario(name)
    g = torch.Generator().manual_seed(seed)
    N = s.num_robots
    layout = make_layouts(s, E, g, device)
    u = lambda: torch.rand(E, N, generator=g)  # noqa: E731
    ti = lambda: torch.randint(0, 3, (E, N), generator=g)  # noqa: E731
    ph = phenotype(
        R_MIN + (R_MAX - R_MIN) * u(),
        ti(),
        ti(),
        ti(),
        u(),
        u(),
        torch.randint(0, 2, (E, N), generator=g),
    )
    progs = bt.random_programs(n_programs, 32, g)
    progs[:4] = torch.stack([bt.template_tensor(k, 32) for k in bt.TEMPLATES][:4])
    rob = Robots.from_phenotype(
        ph, torch.ones(E, N, dtype=torch.bool), torch.randint(0, n_programs, (E, N), generator=g)
    )
    rob = Robots(*(t.to(device) for t in rob))
    return s, layout, rob, bt.build_tables(progs).to(device), WorldParams.for_scenario(s)
