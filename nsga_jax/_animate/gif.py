"""An animation as an animated GIF: each frame drawn by matplotlib (Agg) in
pixel coordinates from :func:`~nsga_jax._animate.screen.frame_shapes`, the
frames joined by Pillow."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from .frames import Animation
from .screen import STYLES, Fit, Shape, View, fit, frame_shapes

DPI = 100
"""Dots per inch of the figure: a line of w px is w × 72 / DPI points wide."""

HOLD_LAST_S = 1.0
"""How long the last frame stays before the GIF starts again [s]."""

PALETTE_SAMPLES = 12
"""Frames sampled for the GIF's one palette (shared by every frame: smaller files, no flicker)."""

DEFAULT_FPS = 20.0
"""Frames per second of the written animations, by default."""


def _points(px: float) -> float:
    return px * 72.0 / DPI


def _collection(group: list[Shape]) -> Any:
    """One matplotlib collection for consecutive shapes of one primitive."""
    from matplotlib.collections import LineCollection, PatchCollection, PolyCollection
    from matplotlib.patches import Circle

    primitive = group[0].shape
    if primitive == "polygon":
        return PolyCollection([s.xy for s in group], facecolors=[s.fill or "none" for s in group],
                              edgecolors=[s.stroke or "none" for s in group],
                              linewidths=[_points(s.width) for s in group], joinstyle="round")
    if primitive == "circle":
        patches = [Circle(tuple(s.xy[0]), s.radius, facecolor=s.fill or "none", edgecolor=s.stroke or "none",
                          linewidth=_points(s.width)) for s in group]
        return PatchCollection(patches, match_original=True)
    lines, colours, widths = [], [], []
    for s in group:
        pieces = [s.xy] if s.shape == "line" else [s.xy[i:i + 2] for i in range(0, len(s.xy) - 1, 2)]
        lines += pieces
        colours += [s.stroke] * len(pieces)
        widths += [_points(s.width)] * len(pieces)
    return LineCollection(lines, colors=colours, linewidths=widths, capstyle="round", joinstyle="round")


def _groups(shapes: list[Shape]) -> list[list[Shape]]:
    """Runs of consecutive shapes of one primitive (lines and segments together), in order."""
    def family(s: Shape) -> str:
        return "stroke" if s.shape in ("line", "segments") else s.shape

    groups: list[list[Shape]] = []
    for s in shapes:
        if groups and family(groups[-1][0]) == family(s):
            groups[-1].append(s)
        else:
            groups.append([s])
    return groups


def label_decimals(times: np.ndarray) -> int:
    """Decimals of the time labels: at least 3, enough to tell two frames apart (at most 9)."""
    steps = np.diff(np.asarray(times, float))
    step = float(steps[steps > 0].min()) if np.any(steps > 0) else 1.0
    return int(min(9, max(3, math.ceil(-math.log10(step) - 1e-9))))


def time_label(t: float, decimals: int = 3) -> str:
    """``t = 0.123 s``, with ``decimals`` decimals."""
    return f"t = {t:.{decimals}f} s"


def render_frames(animation: Animation, view: View = View()) -> list[np.ndarray]:
    """Every frame as an RGB image (height, width, 3), uint8."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fitted: Fit = fit(animation, view)
    decimals = label_decimals(animation.times)
    figure = Figure(figsize=(view.width / DPI, view.height / DPI), dpi=DPI, facecolor="white")
    canvas = FigureCanvasAgg(figure)
    axes = figure.add_axes((0.0, 0.0, 1.0, 1.0))
    axes.set_xlim(0, view.width)
    axes.set_ylim(view.height, 0)
    axes.set_axis_off()
    axes.text(10, 18, animation.title, fontsize=11, va="center", ha="left", color="#202020", zorder=1e4)
    clock = axes.text(view.width - 10, 18, "", fontsize=11, va="center", ha="right", color="#202020",
                      family="monospace", zorder=1e4)
    images = []
    drawn: list[Any] = []
    for frame in range(animation.n_frames):
        for artist in drawn:
            artist.remove()
        drawn = [_collection(group) for group in _groups(frame_shapes(animation, frame, view, fitted))]
        for z, collection in enumerate(drawn):
            collection.set_zorder(z)
            axes.add_collection(collection, autolim=False)
        clock.set_text(time_label(float(animation.times[frame]), decimals))
        canvas.draw()
        images.append(np.asarray(canvas.buffer_rgba())[..., :3].copy())
    return images


def shared_palette(images: list[np.ndarray]) -> Any:
    """One palette for every frame: the colours of :data:`~nsga_jax._animate.screen.STYLES`
    (a contact or an arrow that shows in a few frames keeps its colour), white
    and the text's, then 64 colours fitted to a sample of the frames."""
    from PIL import Image

    exact = {"#ffffff", "#202020"} | {c for style in STYLES.values() for c in (style.fill, style.stroke) if c}
    fixed = [int(c[i:i + 2], 16) for c in sorted(exact) for i in (1, 3, 5)]
    sample = images[:: max(1, len(images) // PALETTE_SAMPLES)]
    fitted = Image.fromarray(np.concatenate(sample, axis=0)).quantize(colors=64, method=Image.Quantize.MEDIANCUT)
    colours = fixed + (fitted.getpalette() or [])[: 3 * 64]
    palette = Image.new("P", (1, 1))
    palette.putpalette(colours + [0] * (768 - len(colours)))
    return palette


def write_gif(animation: Animation, path: str | Path, *, fps: float = DEFAULT_FPS, view: View = View()) -> Path:
    """Write the animation as a looping GIF at ``fps`` frames per second
    (the last frame held :data:`HOLD_LAST_S`); returns the path."""
    from PIL import Image

    path = Path(path)
    images = render_frames(animation, view)
    palette = shared_palette(images)
    frames = [Image.fromarray(image).quantize(palette=palette, dither=Image.Dither.NONE) for image in images]
    step_ms = max(20, int(round(1000.0 / fps)))
    durations = [step_ms] * (len(frames) - 1) + [max(step_ms, int(1000 * HOLD_LAST_S))]
    frames[0].save(path, save_all=True, append_images=frames[1:], duration=durations, loop=0, optimize=True,
                   disposal=1)
    return path


__all__ = ["DEFAULT_FPS", "label_decimals", "render_frames", "time_label", "write_gif"]
