"""An interactive replay page: one self-contained HTML file (`swarmcode-torch replay RUN --html`).

The best team of a run (or of one generation) and its baseline team run through the same
environment, every tick recorded by `episodes.record_episode` (the rollout code of the
evaluation, on the CPU's tick: the fused tick where it builds). The page draws both on canvases
driven by one scrubber, and shows, for a clicked robot, its design, energy, load and behavior
tree with the node that acted that tick; who picked up and delivered each package, per robot
and per design, up to the tick shown (`Episode.credits`); and the tick at which the two arenas
part (`episodes.divergence`).

The focal individual and the baseline. A run made since the replay page records, with each design of a best
team, whether it is the focal individual's (``"focal"``) and its robots in the baseline team the
focal was scored against (``"baseline_count"``); the page takes the baseline from those counts
(the partner slots as they are, the focal's slots refilled to the counts). Older records have
the designs and their robot counts only, so the page reconstructs them (`focal_and_baseline`):
the focal is the design with the most robots (the focal takes slot 0 and its share of the
dominance draws; the first of equals), and the baseline is the team with every slot of the
focal design refilled by the team's other designs (its partners), drawn in proportion to their
dominance (uniformly if all are 0) with a generator seeded by the page's seed, as
`coevo.partners.assemble_swarms` refills them. With no partner the baseline has no robot. The scores are those of this one episode (the record's
fitness is a mean over the run's trials), by the run's fitness weights, budget and objective.

The data (layout, per-tick positions in cm delta-coded over ticks, energies, loads, package
states, the leaf-status combination each robot's tree read) are JSON, gzip-compressed and
base64-encoded inside the page; the browser inflates them with its DecompressionStream. The
script and styles are package data (`replay_page.js`, `replay_page.css`) inlined into the file.
"""

from __future__ import annotations

import base64
import gzip
import hashlib
import html
import json
import math
import re
from collections.abc import Sequence
from functools import partial
from importlib import resources
from pathlib import Path

import torch
from torch import Tensor

from ..coevo.evaluation import team_scores
from ..coevo.fitness import budget_penalty, gate, raw_fitness_terms, team_cost
from ..coevo.population import PINCHER, genome_phenotype
from ..sim import bt
from ..sim.scenario import Scenario
from ..sim.state import DELIVERED, capabilities
from .episodes import DIVERGENCE_EPS, Episode, ProgressFn, divergence, record_episode, team_genome
from .files import atomic_write_bytes, check_output_path
from .render import design_colors
from .replay_explain import seed_marginals
from .replay_teams import focal_and_baseline, species_count

HTML_FILE = "team.html"  # the default output of `replay --html`
_EFFECTOR = {PINCHER: "pincher"}
_TERMS = (
    ("delivery", "deliveries"),
    ("collab", "collaborative deliveries and bonus"),
    ("pickup", "pick-ups"),
    ("energy", "energy left"),
    ("proximity", "proximity"),
    ("closeness", "closeness"),
)


def _rounded(x):
    """Floats (in lists and dicts) rounded as the page's scores are (`_round`)."""
    if isinstance(x, float):
        return _round(x)
    if isinstance(x, list):
        return [_rounded(v) for v in x]
    return {k: _rounded(v) for k, v in x.items()} if isinstance(x, dict) else x


def _stage(progress: ProgressFn, stage: str, _: str, done: int, total: int) -> None:
    progress(stage, done, total)


# ------------------------------------------------------------------ episode -> page data
def _q(x: Tensor, scale: float) -> list[int]:
    """Quantize, then delta-code along the first (tick) axis; flattened."""
    v = torch.round(x.double() * scale).long()
    v = torch.cat([v[:1], v[1:] - v[:-1]]) if v.shape[0] > 1 else v
    return v.reshape(-1).tolist()


def _round(x: float, nd: int = 6) -> float | None:
    return round(float(x), nd) if math.isfinite(float(x)) else None


def _panel(
    ep: Episode,
    team: Tensor,
    programs: Tensor,
    traces: list[dict],
    cost: float,
    species: int,
    cfg,
    scenario: Scenario,
) -> dict:
    """One team's episode as page data; fills `traces` (per design: combination -> trace)."""
    snaps = ep.snapshots
    rob = ep.robots
    stack = {
        k: torch.stack([getattr(s, k) for s in snaps])
        for k in ("pos", "energy", "holding", "grip", "p_pos", "p_status", "holder", "p_picked")
    }
    cap = rob.capacity[0].clamp_min(1e-9)
    present = rob.present[0]
    # the team's mean energy left each tick, as episode_metrics computes it at the end
    pct = 100.0 * stack["energy"] / cap
    n = present.float().sum().clamp_min(1)
    team_energy = (pct * present.float()).sum(-1) / n
    combos = []
    prog = rob.program[0].tolist()
    ops = programs.tolist()
    for t, leaf in enumerate(ep.leaves):
        # the trees that ran at tick t + 1: those of live robots (step's `alive`)
        alive = (present & (snaps[t].energy > 0)).tolist()
        row = torch.where(torch.tensor(alive), bt.combo_index(leaf), -1).tolist()
        for i, ci in enumerate(row):
            if ci >= 0 and ci not in traces[prog[i]]:
                acting, visited = bt.trace(ops[prog[i]], leaf[i].tolist())
                traces[prog[i]][ci] = [acting, [list(v) for v in visited]]
        combos.extend(row)
    m = ep.metrics
    mt = {k: torch.tensor([v]) for k, v in m.items()}
    ecfg = cfg.evaluation(scenario.num_robots, scenario.episode_ticks)
    terms = {k: float(v[0]) for k, v in raw_fitness_terms(mt, ecfg.weights).items()}
    cost_t = torch.tensor([cost])
    penalty = float(budget_penalty(cost_t, ecfg.budget, ecfg.lam)[0])
    score = float(team_scores(mt, cost_t, ecfg)[0])
    return {
        "robots": {
            "design": [r if bool(p) else -1 for r, p in zip(team.tolist(), present.tolist())],
            "radius": [_round(x, 4) for x in rob.radius[0].tolist()],
            "effector": rob.effector[0].tolist(),
            "capacity": [_round(x, 1) for x in rob.capacity[0].tolist()],
            "mass": [_round(x, 3) for x in rob.mass[0].tolist()],
            "payload": [_round(x, 3) for x in rob.payload[0].tolist()],
            "force": [_round(x, 3) for x in rob.force[0].tolist()],
        },
        "pos": _q(stack["pos"], 100.0),  # cm, delta over ticks [T+1, N, 2]
        "energy": _q(pct, 10.0),  # 0.1 %, delta [T+1, N]
        "team_energy": team_energy.tolist(),
        "holding": stack["holding"].reshape(-1).tolist(),  # [T+1, N]
        "grip": stack["grip"].reshape(-1).tolist(),
        "p_pos": _q(stack["p_pos"], 100.0),  # [T+1, Q, 2]
        "p_status": stack["p_status"].reshape(-1).tolist(),
        "holder": stack["holder"].reshape(-1).tolist(),  # [T+1, Q, G]
        "p_picked": stack["p_picked"].long().reshape(-1).tolist(),
        "combo": combos,  # [T, N] ticks 1..T, -1: no tree ran
        # (tick, robot, package, kind) of each pick-up and delivery, flat (episodes.CREDIT_KINDS)
        "credits": [x for c in ep.credits for x in c],
        "tick_mode": ep.tick,
        "metrics": {k: _round(v) for k, v in m.items()},
        "terms": {k: _round(v) for k, v in terms.items()},
        "raw": _round(float(sum(terms[k] for k, _ in _TERMS) * terms["activity"])),
        "floor": ecfg.weights.floor,
        "penalty": _round(penalty),
        "cost": _round(cost, 2),
        "species": species,
        "score": _round(score),
    }


def page_data(
    designs: Sequence[dict],
    scenario: Scenario,
    cfg,
    seed: int = 0,
    ticks: int | None = None,
    title: str = "",
    record: dict | None = None,
    progress: ProgressFn | None = None,
    seeds: int = 1,
) -> dict:
    """Everything the page shows, as JSON-friendly data: both teams' episodes in the environment
    of `seed`, the designs, the layout, the scores, who picked up and delivered what, and the
    tick at which the two arenas part (`episodes.divergence`: the first at which a robot of a
    slot both teams share stands apart). `cfg`: the run's SwarmCoDeConfig.
    `progress(stage, done, total)`: stages "focal ticks" and "baseline ticks". `seeds` > 1:
    the two teams' marginal over that many environments too (`replay_seeds.seed_marginals`)."""
    genome, _ = team_genome(designs, cfg.tag_length)
    focal, team, base, recorded = focal_and_baseline(designs, seed)
    ticks = scenario.episode_ticks if ticks is None else int(ticks)
    ph = genome_phenotype(genome, scenario.hardware)
    traces: list[dict] = [{} for _ in designs]
    panels, eps = {}, {}
    for name, t in (("focal", team), ("baseline", base)):
        tell = None if progress is None else partial(_stage, progress, f"{name} ticks")
        panels[name], eps[name] = _record_panel(
            designs, genome, ph.cost, t, traces, scenario, cfg, seed, ticks, tell
        )
    f, b = panels["focal"]["score"], panels["baseline"]["score"]
    part = divergence(eps["focal"], eps["baseline"], (team == base) & (team >= 0))
    gated = float(gate(torch.tensor([f]), torch.tensor([b]), cfg.p_marginal)[0])
    lay = eps["focal"].layout
    o = lay.o_present[0]
    Q, G = lay.g_effector.shape[1:]
    return {
        "title": title,
        "scenario": scenario.name,
        "seed": int(seed),
        "ticks": ticks,
        "dt": eps["focal"].params.dt,
        "arena": scenario.arena,
        "base_radius": scenario.base_radius,
        "robots": int(team.numel()),
        "Q": int(Q),
        "G": int(G),
        "record": record or {},
        "objective": cfg.objective,
        "budget": cfg.budget,
        "custom_fitness": getattr(cfg, "fitness_function", None),
        "weights": {k: getattr(cfg.fitness_weights, k) for k in _WEIGHTS},
        "classes": [c.label for c in scenario.packages],
        "packages": _package_data(lay, scenario),
        "obstacles": [
            [_round(x, 3), _round(y, 3), _round(r, 3)]
            for (x, y), r in zip(lay.o_pos[0][o].tolist(), lay.o_radius[0][o].tolist())
        ],
        "designs": _design_data(designs, genome, ph, base, focal, traces, scenario, eps["focal"]),
        "focal": focal,
        "baseline_recorded": recorded,
        "panels": panels,
        "gated": _round(gated),
        "marginal": _round(f - b),
        # the first tick the arenas part at, and the slot of the robot that stands apart first
        "divergence": None if part is None else {"tick": part[0], "robot": part[1]},
        "divergence_eps": DIVERGENCE_EPS,
        "seed_marginals": _rounded(seed_marginals(designs, scenario, cfg, seed, seeds, ticks))
        if seeds > 1
        else None,
        "shared_slots": int(((team == base) & (team >= 0)).sum()),
        "p_marginal": cfg.p_marginal,
    }


#: The fitness weights the page shows (and scores a panel with)
_WEIGHTS = (
    "W_delivery",
    "W_collab_bonus",
    "W_pickup",
    "W_energy",
    "W_proximity",
    "W_closeness",
    "inactive_factor",
    "floor",
)


def _record_panel(designs, genome, row_cost, t, traces, scenario, cfg, seed, ticks, tell):
    """One team's (`t`: the genome row of each slot, -1 empty) panel: its episode recorded every
    tick with the leaves its trees read (the slots each tree visits added to `traces`), its
    cost and score. (panel, episode)."""
    ep = record_episode(genome, t, scenario, seed, ticks=ticks, every=1, leaves=True, progress=tell)
    present = t >= 0
    counts = torch.tensor([species_count(designs, t)])
    cost = float(team_cost(row_cost[t.clamp_min(0)], present, counts, scenario.species_overhead)[0])
    return _panel(ep, t, genome.bt, traces, cost, int(counts[0]), cfg, scenario), ep


def _package_data(lay, scenario: Scenario) -> dict:
    """The packages of the layout as the page draws them: present, class, collaborative, size,
    mass and its colour (darker = heavier), grips."""
    from matplotlib import colormaps
    from matplotlib.colors import to_hex

    Q = lay.g_effector.shape[1]
    present = lay.p_present[0]
    cls = [i for i, c in enumerate(scenario.packages) for _ in range(c.count)]
    mass = lay.p_mass[0]
    pm = mass[present]
    lo, hi = (float(pm.min()), float(pm.max())) if pm.numel() else (0.0, 1.0)
    ylor = colormaps["YlOrBr"]
    pcol = [
        to_hex(ylor(0.35 + 0.6 * min(max((float(x) - lo) / max(hi - lo, 1e-6), 0), 1)))
        for x in mass.tolist()
    ]
    return {
        "present": present.long().tolist(),
        "cls": cls + [-1] * (int(Q) - len(cls)),
        "collab": lay.p_collab[0].long().tolist(),
        "size": [_round(x, 4) for x in lay.p_size[0].tolist()],
        "mass": [_round(x, 3) for x in mass.tolist()],
        "color": pcol,
        "g_eff": lay.g_effector[0].reshape(-1).tolist(),
        "g_off": [_round(x, 4) for x in lay.g_offset[0].reshape(-1).tolist()],
    }


def _design_data(designs, genome, ph, base, focal, traces, scenario, ep) -> list[dict]:
    """Each design as the page shows it: its hardware, cost, capability, counts in both teams,
    colour, tree and the slots its tree visited (`traces`)."""
    from matplotlib.colors import to_hex

    colors = design_colors(len(designs))
    if all("capability" in d for d in designs):
        can = [list(d["capability"]) for d in designs]
    else:  # an older record: from the genes, as analysis.design_capabilities does
        rows = capabilities(ph, scenario, ep.params).tolist()
        can = [[j for j, ok in enumerate(r) if ok] for r in rows]
    dd = []
    for i, d in enumerate(designs):
        dd.append(
            {
                "species": d.get("species"),
                "effector": d["effector"]
                if isinstance(d["effector"], str)
                else _EFFECTOR.get(int(d["effector"]), "suction"),
                "radius": d["radius"],
                "chassis_tier": d["chassis_tier"],
                "battery_tier": d["battery_tier"],
                "motor_tier": d["motor_tier"],
                "torque_point": d["torque_point"],
                "battery_point": d["battery_point"],
                "dominance": d.get("dominance"),
                "selectivity": d.get("selectivity"),
                "cost": _round(float(ph.cost[i]), 2),
                "capability": can[i],
                "count": int(d.get("count", 1)),
                "baseline_count": int((base == i).sum()),
                "color": to_hex(colors[i]),
                "focal": i == focal,
                "tree": [[text, slot] for text, slot in bt.tree_lines(genome.bt[i].tolist())],
                "ops": genome.bt[i].tolist(),
                "traces": {str(k): v for k, v in sorted(traces[i].items())},
            }
        )
    return dd


def final_counts(data: dict, panel: str) -> dict:
    """The counts the page shows at the last tick, computed from the page data as the page
    computes them: deliveries (individual, collaborative), packages picked, energy used."""
    p = data["panels"][panel]
    Q, T = data["Q"], data["ticks"]
    pk = data["packages"]
    last = slice(T * Q, (T + 1) * Q)
    st, picked = p["p_status"][last], p["p_picked"][last]
    out = {
        "delivered_individual": 0,
        "delivered_collab": 0,
        "picked_individual": 0,
        "picked_collab": 0,
    }
    for q in range(Q):
        if not pk["present"][q]:
            continue
        kind = "collab" if pk["collab"][q] else "individual"
        out["delivered_" + kind] += st[q] == DELIVERED
        out["picked_" + kind] += picked[q]
    out["energy_used"] = 100.0 - p["team_energy"][T]
    return out


# ------------------------------------------------------------------ the file
def _asset(name: str) -> str:
    return resources.files(__package__).joinpath(name).read_text(encoding="utf-8")


def content_security_policy(script: str) -> str:
    """The page's policy: nothing is loaded from anywhere, and the one script that may run is the
    page's own, named by its SHA-256; inline event handlers (`onerror=`, `onload=`) and any other
    script, planted in run data or not, are refused by the browser."""
    digest = base64.b64encode(hashlib.sha256(script.encode("utf-8")).digest()).decode("ascii")
    return (
        f"default-src 'none'; script-src 'sha256-{digest}'; style-src 'unsafe-inline'; "
        "img-src data:; base-uri 'none'; form-action 'none'"
    )


def render_html(data: dict) -> str:
    """The page: the template with its script, styles and the gzip + base64 data inlined."""
    raw = json.dumps(data, separators=(",", ":"), allow_nan=False).encode()
    blob = base64.b64encode(gzip.compress(raw, compresslevel=9, mtime=0)).decode("ascii")
    # the script must not close its own tag; the data is base64, which has no '<'
    script = _asset("replay_page.js").replace("</script", "<\\/script")
    parts = {
        "@CSP@": content_security_policy(script),
        "/*STYLE*/": _asset("replay_page.css"),
        "/*SCRIPT*/": script,
        "@TITLE@": html.escape(data.get("title") or "SwarmCoDe replay"),
        "@DATA@": blob,
    }
    # one pass over the template: nothing inserted is searched for markers again
    return re.sub(
        "|".join(re.escape(k) for k in parts),
        lambda m: parts[m.group(0)],
        _asset("replay_page.html"),
    )


def decode_page(text: str) -> dict:
    """The data inside a page written by `render_html` (for tests and tools)."""
    start = text.index('id="episode-data"')
    start = text.index(">", start) + 1
    end = text.index("</script>", start)
    return json.loads(gzip.decompress(base64.b64decode(text[start:end].strip())))


def write_page(data: dict, path: str | Path) -> Path:
    """Write the page atomically beside `path`; a link, device or FIFO there is refused."""
    path = check_output_path(Path(path))
    atomic_write_bytes(path, render_html(data).encode("utf-8"))
    return path
