"""Replays of one team in one environment: recording, drawing, GIF / PNG export.

`record_episode` (`episodes`) runs a team through one random environment of a scenario on the
CPU and keeps snapshots of the state; `draw_frame` draws a snapshot on a matplotlib Axes in true
arena coordinates; `draw_static` and `frame_title` are what `frames` builds its fast frames on
(`frames.save_gif`, `frames.save_png` and `frames.frame_image` turn an episode into pictures;
`analysis.replay_run` does it all for the best team of a run directory).

Matplotlib (Agg canvas, no pyplot) and PIL are imported inside the functions that need them.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from ..coevo.population import PINCHER, SUCTION
from ..sim.state import DELIVERED, State
from .episodes import _EFFECTOR_NAMES, Episode, record_episode, team_genome

__all__ = ["Episode", "design_colors", "draw_frame", "record_episode", "team_genome"]
# tab10, most distinct hues first; brown / olive / grey last (packages are drawn in browns).
_TAB10_ORDER = (0, 2, 3, 4, 6, 9, 1, 7, 8, 5)


# ------------------------------------------------------------------ drawing
def design_colors(n: int) -> list:
    """`n` RGBA colours from tab10, one per design row (cycling after 10)."""
    from matplotlib import colormaps

    cmap = colormaps["tab10"]
    return [cmap(_TAB10_ORDER[i % 10]) for i in range(n)]


def _mass_colors(episode: Episode, mass: Tensor) -> list:
    """Package face colours: light orange (light packages) to dark brown (heavy), over the
    episode; the lightest is a clear orange, never the white of a free grip marker."""
    from matplotlib import colormaps

    cmap = colormaps["YlOrBr"]
    lay = episode.layout
    all_m = lay.p_mass[0][lay.p_present[0]]
    lo, hi = (float(all_m.min()), float(all_m.max())) if all_m.numel() else (0.0, 1.0)
    frac = ((mass - lo) / max(hi - lo, 1e-6)).clamp(0, 1)
    return [cmap(0.35 + 0.6 * float(f)) for f in frac]


def draw_frame(
    ax, episode: Episode, snapshot: State, colors: Sequence | None = None, legend: bool = True
) -> None:
    """Draw one snapshot on a matplotlib Axes (cleared first), in arena coordinates (m).

    Grey discs: obstacles; green disc: the base. Packages on the ground or carried: squares
    need a pincher, circles suction, shaded light to dark brown by mass; collaborative packages
    are hexagons with a marker per grip point (square pincher / circle suction, filled black
    when held). Robots: discs of their true radius coloured by design row, marked with their
    effector (an inner square outline: pincher, an inner ring: suction, the shapes of the
    packages each lifts); a thick black outline when carrying, faded when the battery is flat.
    """
    colors = list(colors) if colors is not None else design_colors(max(episode.num_designs, 1))
    draw_static(ax, episode, colors, legend)
    _draw_moving(ax, episode, snapshot, colors)


def draw_static(ax, episode: Episode, colors: Sequence, legend: bool = True) -> None:
    """What stays put over an episode (the Axes cleared first): arena, base, obstacles, and the
    legend of the designs and package kinds."""
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Circle, Rectangle

    lay, prm = episode.layout, episode.params
    W = prm.arena
    ax.clear()
    ax.set_xlim(-0.2, W + 0.2)
    ax.set_ylim(-0.2, W + 0.2)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    for sp in ax.spines.values():
        sp.set_visible(False)

    # arena, base, obstacles
    ax.add_patch(Rectangle((0, 0), W, W, facecolor="white", edgecolor="black", lw=1.2, zorder=0))
    ax.add_patch(
        Circle(
            (W / 2, W / 2),
            prm.base_radius,
            facecolor="#cfeccf",
            edgecolor="#3a8a3a",
            lw=1.0,
            zorder=1,
        )
    )
    o_keep = lay.o_present[0]
    obst = [
        Circle(tuple(p), float(r))
        for p, r in zip(lay.o_pos[0][o_keep].tolist(), lay.o_radius[0][o_keep].tolist())
    ]
    if obst:
        ax.add_collection(
            PatchCollection(obst, facecolor="#9a9a9a", edgecolor="#555555", lw=0.8, zorder=2)
        )
    if legend and episode.labels:
        _legend(ax, episode, colors)


def _draw_moving(ax, episode: Episode, snapshot: State, colors: Sequence) -> None:
    """Packages, robots and the title of one snapshot (over `draw_static`)."""
    from matplotlib.collections import PatchCollection

    s = snapshot
    ground, ground_c, carried, carried_c, grips = _package_patches(episode, s)
    if ground:
        ax.add_collection(
            PatchCollection(ground, facecolor=ground_c, edgecolor="black", lw=0.6, zorder=3)
        )
    _draw_robots(ax, episode, s, colors)
    if carried:
        ax.add_collection(
            PatchCollection(carried, facecolor=carried_c, edgecolor="black", lw=0.6, zorder=5)
        )
    for patches, fills in grips:
        if patches:
            ax.add_collection(
                PatchCollection(patches, facecolor=fills, edgecolor="black", lw=0.7, zorder=6)
            )

    ax.set_title(frame_title(episode, s), fontsize=9)


def _package_patches(episode: Episode, s: State) -> tuple[list, list, list, list, list]:
    """The packages not delivered as patches: (those on the ground, their colours, those
    carried, drawn small on their carriers, their colours, [(the pincher grips of collaborative
    packages, their fills), (the suction grips, their fills)])."""
    from matplotlib.patches import Circle, Rectangle, RegularPolygon

    lay, rob = episode.layout, episode.robots
    present = lay.p_present[0] & (s.p_status != DELIVERED)
    holder = s.holder  # [P, G]
    g_eff = lay.g_effector[0]  # [P, G]
    idx = torch.nonzero(present).flatten().tolist()
    face = _mass_colors(episode, lay.p_mass[0])
    ground, carried, ground_c, carried_c = [], [], [], []
    grips_p, grips_s, grip_fill_p, grip_fill_s = [], [], [], []
    for p in idx:
        x, y = s.p_pos[p].tolist()
        size = float(lay.p_size[0, p])
        held = bool((holder[p] >= 0).any())
        if bool(lay.p_collab[0, p]):
            ground.append(RegularPolygon((x, y), 6, radius=size * 1.05))
            ground_c.append(face[p])
            for g in range(g_eff.shape[1]):
                e = int(g_eff[p, g])
                if e < 0:
                    continue
                gx, gy = (s.p_pos[p] + lay.g_offset[0, p, g]).tolist()
                taken = int(holder[p, g]) >= 0  # held: small and black, on its robot
                fill, h = ("black", 0.07) if taken else ("white", 0.11)
                if e == PINCHER:
                    grips_p.append(Rectangle((gx - h, gy - h), 2 * h, 2 * h))
                    grip_fill_p.append(fill)
                else:
                    grips_s.append(Circle((gx, gy), h * 1.1))
                    grip_fill_s.append(fill)
        else:
            e = int(g_eff[p, 0])
            r = size
            if held:  # drawn small on top of its carrier, so that the robot's colour shows
                carrier = int(holder[p, 0])
                r = min(size, 0.5 * float(rob.radius[0, carrier]))
            if e == PINCHER:
                h = r * 0.9
                patch = Rectangle((x - h, y - h), 2 * h, 2 * h)
            else:
                patch = Circle((x, y), r)
            (carried if held else ground).append(patch)
            (carried_c if held else ground_c).append(face[p])
    return ground, ground_c, carried, carried_c, [(grips_p, grip_fill_p), (grips_s, grip_fill_s)]


def _draw_robots(ax, episode: Episode, s: State, colors: Sequence) -> None:
    """Every robot present as a disc of its design's colour (faded when out of energy, a dark
    edge when carrying) with its effector's mark."""
    from matplotlib.collections import PatchCollection
    from matplotlib.colors import to_rgba
    from matplotlib.patches import Circle, Rectangle

    rob = episode.robots
    keep = rob.present[0].tolist()
    prog = rob.program[0].tolist()
    radius = rob.radius[0].tolist()
    pos = s.pos.tolist()
    carrying = (s.holding >= 0).tolist()
    alive = (s.energy > 0).tolist()
    effector = rob.effector[0].tolist()
    discs, fc, ec, lw, marks = [], [], [], [], []
    for i in range(len(keep)):
        if not keep[i]:
            continue
        discs.append(Circle(tuple(pos[i]), radius[i]))
        x, y = pos[i]
        if effector[i] == PINCHER:
            h = 0.42 * radius[i]
            marks.append(Rectangle((x - h, y - h), 2 * h, 2 * h))
        else:
            marks.append(Circle((x, y), 0.48 * radius[i]))
        c = to_rgba(colors[prog[i] % len(colors)])
        fc.append(c if alive[i] else c[:3] + (0.3,))
        ec.append("black" if carrying[i] else "#444444")
        lw.append(1.2 if carrying[i] else 0.4)
    if discs:
        ax.add_collection(
            PatchCollection(discs, facecolor=fc, edgecolor=ec, linewidths=lw, zorder=4)
        )
        ax.add_collection(
            PatchCollection(
                marks, facecolor="none", edgecolor="#1a1a1a", linewidths=0.9, zorder=4.5
            )
        )


def frame_title(episode: Episode, s: State) -> str:
    """A frame's title: the scenario, the tick and the deliveries so far."""
    lay = episode.layout
    done = (s.p_status == DELIVERED) & lay.p_present[0]
    collab = lay.p_collab[0]
    n_ind, n_col = int((done & ~collab).sum()), int((done & collab).sum())
    total = int(lay.p_present[0].sum())
    extra = f" ({n_ind} indiv, {n_col} collab)" if bool(collab.any()) else ""
    name = f"{episode.name}  " if episode.name else ""
    return f"{name}tick {int(s.t)}   delivered {n_ind + n_col}/{total}{extra}"


def _mark(marker: str, size: float, face, edge="black", **kw):
    """A legend's mark: a marker alone (no line)."""
    from matplotlib.lines import Line2D

    return Line2D(
        [],
        [],
        marker=marker,
        ls="",
        markersize=size,
        markeredgecolor=edge,
        markerfacecolor=face,
        **kw,
    )


def _legend(ax, episode: Episode, colors: Sequence) -> None:
    """The legend: each design present with its mark, then the package kinds present."""
    lay, rob = episode.layout, episode.robots
    keep = rob.present[0].tolist()
    prog = rob.program[0].tolist()
    effector = rob.effector[0].tolist()
    g_eff = lay.g_effector[0]
    collab = lay.p_collab[0]

    used = sorted(set(p for p, k in zip(prog, keep) if k))
    eff_of = {p: e for p, e, k in zip(prog, effector, keep) if k}
    handles = [
        (
            _mark("o", 9, colors[r % len(colors)], edge="#333333"),
            _mark(
                "s" if eff_of[r] == PINCHER else "o", 4, "none", edge="#1a1a1a", markeredgewidth=0.9
            ),
        )
        for r in used
    ]
    labels = [episode.labels[r] if r < len(episode.labels) else f"design {r}" for r in used]
    kinds = lay.p_present[0]
    indiv_eff = set(g_eff[kinds & ~collab, 0].tolist())
    pkg = "#d9a35b"
    for e, m in ((PINCHER, "s"), (SUCTION, "o")):
        if e in indiv_eff:
            handles.append(_mark(m, 6, pkg))
            labels.append(f"{_EFFECTOR_NAMES[e]} package")
    if bool((kinds & collab).any()):
        handles.append(_mark("h", 8, pkg))
        labels.append("collab package")
        grip_eff = set(g_eff[kinds & collab].flatten().tolist())
        for e, m in ((PINCHER, "s"), (SUCTION, "o")):
            if e in grip_eff:
                handles.append(_mark(m, 4, "white"))
                labels.append(f"{_EFFECTOR_NAMES[e]} grip")
        handles.append(_mark("o", 4, "black"))
        labels.append("held grip")
    ax.legend(
        handles,
        labels,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        fontsize=8,
        frameon=False,
        handletextpad=0.3,
        borderaxespad=0.0,
        title="darker = heavier",
        title_fontsize=8,
    )
