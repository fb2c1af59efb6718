"""Frames of a recorded episode, fast: what stays put (arena, base, obstacles, legend) drawn
once by matplotlib (`render.draw_static`), what moves (packages, robots, the title) drawn on a
copy of it by PIL at twice the resolution and reduced (antialiased), so a frame costs a few
milliseconds rather than a matplotlib figure's redraw. The shapes and colours are those of
`render.draw_frame`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path

from ..coevo.population import PINCHER
from ..sim.state import DELIVERED, State
from .episodes import Episode
from .render import _mass_colors, design_colors, draw_static, frame_title

_SS = 2  # supersampling: frames are drawn at twice the size, then reduced


def _rgb(c) -> tuple[int, int, int]:
    from matplotlib.colors import to_rgb

    r, g, b = to_rgb(c)
    return (round(255 * r), round(255 * g), round(255 * b))


def _faded(c: tuple[int, int, int], alpha: float = 0.3) -> tuple[int, int, int]:
    """`c` at `alpha` over white (a robot with a flat battery)."""
    return tuple(round(alpha * v + (1 - alpha) * 255) for v in c)  # type: ignore[return-value]


class FrameRenderer:
    """Draws the snapshots of one episode as ``[H, W, 3]`` uint8 images (`render`) or PIL
    images (`image`), all of the same size: `size` inches at `dpi`, as `render._Canvas` did."""

    def __init__(self, episode: Episode, dpi: int = 80, size: tuple[float, float] = (7.0, 5.2)):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
        from matplotlib.font_manager import FontProperties, findfont
        from PIL import Image, ImageFont

        self.episode = episode
        colors = design_colors(max(episode.num_designs, 1))
        fig = Figure(figsize=size, dpi=dpi * _SS)
        canvas = FigureCanvasAgg(fig)
        ax = fig.add_axes((0.01, 0.01, 0.71, 0.93))
        draw_static(ax, episode, colors)
        canvas.draw()
        w, h = canvas.get_width_height()
        self.background = Image.frombuffer("RGBA", (w, h), canvas.buffer_rgba()).convert("RGB")
        (x0, y0), (x1, y1) = ax.transData.transform([(0.0, 0.0), (1.0, 1.0)])
        self.sx, self.sy, self.ox, self.oy, self.h = x1 - x0, y1 - y0, x0, y0, h
        bbox = ax.get_position()  # figure fraction
        self.title_xy = ((bbox.x0 + bbox.x1) / 2 * w, h - bbox.y1 * h - 6 * dpi * _SS / 72)
        self.pt = dpi * _SS / 72  # pixels per point
        self.font = ImageFont.truetype(findfont(FontProperties(family="DejaVu Sans")), 9 * self.pt)
        rob, lay = episode.robots, episode.layout
        self.robot_rgb = [_rgb(colors[p % len(colors)]) for p in rob.program[0].tolist()]
        self.package_rgb = [_rgb(c) for c in _mass_colors(episode, lay.p_mass[0])]

    def _px(self, x: float, y: float) -> tuple[float, float]:
        return self.ox + self.sx * x, self.h - (self.oy + self.sy * y)

    def _w(self, points: float) -> int:
        return max(1, round(points * self.pt))

    def _shape(self, d, eff: int, x: float, y: float, r: float, **kw) -> None:
        """A square (pincher, half-side `r`) or a disc (suction, radius `r`), pixels."""
        box = (x - r, y - r, x + r, y + r)
        (d.rectangle if eff == PINCHER else d.ellipse)(box, **kw)

    def image(self, s: State):
        """Snapshot `s` as a PIL RGB image."""
        from PIL import ImageDraw

        ep, lay, rob = self.episode, self.episode.layout, self.episode.robots
        im = self.background.copy()
        d = ImageDraw.Draw(im)
        black, thin = (0, 0, 0), self._w(0.6)
        g_eff = lay.g_effector[0].tolist()
        sizes = lay.p_size[0].tolist()
        collab = lay.p_collab[0].tolist()
        show = (lay.p_present[0] & (s.p_status != DELIVERED)).tolist()
        p_pos, holder = s.p_pos.tolist(), s.holder.tolist()
        offsets = lay.g_offset[0].tolist()
        radius = rob.radius[0].tolist()
        carried, grips = [], []
        for q, on in enumerate(show):
            if not on:
                continue
            px, py = p_pos[q]
            x, y = self._px(px, py)
            held = [i for i in holder[q] if i >= 0]
            if collab[q]:
                r = sizes[q] * 1.05 * self.sx
                hexagon = [
                    (x + r * math.cos(math.pi / 2 + k * math.pi / 3),
                     y - r * math.sin(math.pi / 2 + k * math.pi / 3))
                    for k in range(6)
                ]  # fmt: skip
                d.polygon(hexagon, fill=self.package_rgb[q], outline=black, width=thin)
                for g, e in enumerate(g_eff[q]):
                    if e >= 0:
                        gx, gy = offsets[q][g]
                        grips.append((e, px + gx, py + gy, holder[q][g] >= 0))
            elif held:
                carried.append((q, x, y, min(sizes[q], 0.5 * radius[held[0]])))
            else:
                r = sizes[q] * self.sx * (0.9 if g_eff[q][0] == PINCHER else 1.0)
                self._shape(d, g_eff[q][0], x, y, r, fill=self.package_rgb[q], outline=black,
                            width=thin)  # fmt: skip
        pos, carrying = s.pos.tolist(), (s.holding >= 0).tolist()
        alive, effector = (s.energy > 0).tolist(), rob.effector[0].tolist()
        for i, on in enumerate(rob.present[0].tolist()):
            if not on:
                continue
            x, y = self._px(*pos[i])
            r = radius[i] * self.sx
            fill = self.robot_rgb[i] if alive[i] else _faded(self.robot_rgb[i])
            edge = black if carrying[i] else (0x44, 0x44, 0x44)
            d.ellipse((x - r, y - r, x + r, y + r), fill=fill, outline=edge,
                      width=self._w(1.2 if carrying[i] else 0.4))  # fmt: skip
            m = r * (0.42 if effector[i] == PINCHER else 0.48)
            self._shape(d, effector[i], x, y, m, outline=(0x1A, 0x1A, 0x1A), width=self._w(0.9))
        for q, x, y, r in carried:  # small, on top of the carrier, so its colour shows
            r = r * self.sx * (0.9 if g_eff[q][0] == PINCHER else 1.0)
            self._shape(d, g_eff[q][0], x, y, r, fill=self.package_rgb[q], outline=black,
                        width=thin)  # fmt: skip
        for e, gx, gy, taken in grips:
            x, y = self._px(gx, gy)
            h = (0.07 if taken else 0.11) * self.sx * (1.0 if e == PINCHER else 1.1)
            self._shape(d, e, x, y, h, fill=black if taken else (255, 255, 255), outline=black,
                        width=self._w(0.7))  # fmt: skip
        d.text(self.title_xy, frame_title(ep, s), fill=black, font=self.font, anchor="mb")
        return im.reduce(_SS)

    def render(self, s: State):
        """Snapshot `s` as a numpy uint8 array ``[H, W, 3]``."""
        import numpy as np

        return np.asarray(self.image(s)).copy()


def gif_frames(
    episode: Episode, dpi: int = 80, progress: Callable[[str, int, int], None] | None = None
) -> Sequence:
    """Every snapshot as a palette image, all on one palette (of the first and last frames:
    the same colours throughout, and frames that differ only where something moved, which a
    GIF stores compactly). `progress("frames", done, total)` as they are drawn."""
    from PIL import Image

    cv = FrameRenderer(episode, dpi)
    snaps = episode.snapshots
    n = len(snaps)
    first, last = cv.image(snaps[0]), cv.image(snaps[-1])
    both = Image.new("RGB", (first.width * 2, first.height))
    both.paste(first, (0, 0))
    both.paste(last, (first.width, 0))
    palette = both.quantize(colors=128, method=Image.Quantize.MEDIANCUT)
    out = []
    for i, s in enumerate(snaps):
        im = first if i == 0 else last if i == n - 1 else cv.image(s)
        out.append(im.quantize(palette=palette, dither=Image.Dither.NONE))
        if progress is not None and (i % 5 == 0 or i == n - 1):
            progress("frames", i + 1, n)
    return out


def frame_image(episode: Episode, index: int = -1, dpi: int = 80):
    """Snapshot `index` as a numpy uint8 array ``[H, W, 3]`` (TensorBoard: dataformats="HWC")."""
    return FrameRenderer(episode, dpi).render(episode.snapshots[index])


def save_png(episode: Episode, path: str | Path, index: int = -1, dpi: int = 100) -> Path:
    """Write snapshot `index` (default the last) as a PNG."""
    path = Path(path)
    FrameRenderer(episode, dpi).image(episode.snapshots[index]).save(path, format="PNG")
    return path


def save_gif(
    episode: Episode,
    path: str | Path,
    fps: float = 10,
    dpi: int = 80,
    progress: Callable[[str, int, int], None] | None = None,
) -> Path:
    """Write every snapshot of the episode as an animated GIF (looping) to `path` (a file name,
    or a binary file object); `progress("frames", done, total)` as the frames are drawn."""
    path = Path(path) if isinstance(path, (str, Path)) else path
    frames = gif_frames(episode, dpi, progress)
    duration = max(int(round(1000.0 / fps)), 20)
    frames[0].save(
        path,
        format="GIF",
        save_all=True,
        append_images=list(frames[1:]),
        duration=duration,
        loop=0,
        optimize=False,
    )
    return path
