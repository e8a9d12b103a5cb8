"""An animation as one self-contained HTML page: the frames as inline JSON
and a small canvas player (``player.js``, inline too) with play/pause, a
frame slider and, for a 3D drawing, drag to turn the view (double-click:
back to the first view). The page loads nothing: no script, style sheet,
font or image from anywhere else.

``page.html#frame=K`` opens the page paused at frame K; ``#view=A,E`` (3D)
opens it seen from azimuth A and elevation E [degrees] (``#frame=K&view=A,E``: both).
"""

from __future__ import annotations

import html
import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from .frames import Animation
from .gif import DEFAULT_FPS, HOLD_LAST_S, label_decimals, time_label
from .screen import MARGIN, SPRING_COILS, TITLE_BAND, View, styles_table

PLAYER = Path(__file__).with_name("player.js")
"""The player's source, inlined into every page."""

RESOLUTION = 1e-4
"""Coordinates are written to this fraction of the drawing's size (a tenth of a pixel on a 1000-pixel view)."""

CONTROLS_HEIGHT = 44
"""Height of the controls bar at the bottom of the page [CSS px]; the canvas fills the rest of the window."""

DATA_PATTERN = re.compile(r'<script id="animation-data" type="application/json">(.*?)</script>', re.S)

PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{title} - nsga_jax</title>
<style>
html, body {{ margin: 0; height: 100%; overflow: hidden; background: #ffffff; font: 14px sans-serif; }}
#view {{ display: block; touch-action: none; }}
#controls {{ position: fixed; left: 0; right: 0; bottom: 0; height: {controls}px; box-sizing: border-box;
  display: flex; align-items: center; gap: 10px; padding: 0 10px; border-top: 1px solid #dddddd;
  background: #f6f6f6; }}
#frame {{ flex: 1; }}
#time {{ font-family: monospace; white-space: pre; }}
</style>
</head>
<body>
<canvas id="view"></canvas>
<div id="controls"><button id="play" type="button">Pause</button><input id="frame" type="range" min="0" max="0" \
value="0" aria-label="frame"><span id="time"></span></div>
<script id="animation-data" type="application/json">{data}</script>
<script>
{player}</script>
</body>
</html>
"""


def _decimals(size: float) -> int:
    """Decimals [m] that resolve :data:`RESOLUTION` of a drawing of ``size`` [m]."""
    return max(0, int(math.ceil(-math.log10(RESOLUTION * size))))


def _points_field(points: tuple[int, ...]) -> dict[str, Any]:
    """An item's point indices; a run of consecutive ones as ``range: [first, count]``."""
    if len(points) > 4 and points == tuple(range(points[0], points[0] + len(points))):
        return {"range": [points[0], len(points)]}
    return {"points": list(points)}


def animation_data(animation: Animation, *, fps: float = DEFAULT_FPS, view: View = View()) -> dict[str, Any]:
    """What the page carries: the animation (coordinates rounded to
    :data:`RESOLUTION` of its size), the look of every kind, the first view
    and the playback rate."""
    decimals = _decimals(animation.size)
    items = []
    for item in animation.items:
        entry: dict[str, Any] = {"kind": item.kind, "shape": item.shape, **_points_field(item.points)}
        if item.radius:
            entry["radius"] = item.radius
        if item.part:
            entry["part"] = item.part
        items.append(entry)
    active = {str(i): "".join("1" if a else "0" for a in animation.active[:, i])
              for i in range(len(animation.items)) if not animation.active[:, i].all()}
    return {
        "title": animation.title, "dim": animation.dim, "up": animation.up.tolist(),
        "times": [float(f"{t:.9g}") for t in animation.times],
        "labels": [time_label(float(t), label_decimals(animation.times)) for t in animation.times],
        "fps": fps, "holdLast": HOLD_LAST_S,
        "view": {"azimuth": view.azimuth, "elevation": view.elevation},
        "margin": MARGIN, "titleBand": TITLE_BAND, "springCoils": SPRING_COILS, "styles": styles_table(),
        "focus": np.round(animation.focus, decimals).tolist(),
        "items": items, "active": active,
        "moving": np.round(animation.moving, decimals).reshape(animation.n_frames, -1).tolist(),
        "fixed": np.round(animation.fixed, decimals).reshape(-1).tolist(),
    }


def page(animation: Animation, *, fps: float = DEFAULT_FPS, view: View = View()) -> str:
    """The HTML page of the animation (see the module)."""
    data = json.dumps(animation_data(animation, fps=fps, view=view), separators=(",", ":"), allow_nan=False)
    data = data.replace("</", "<\\/")  # no "</script>" inside the data
    return PAGE.format(title=html.escape(animation.title), data=data, player=PLAYER.read_text(),
                       controls=CONTROLS_HEIGHT)


def write_html(animation: Animation, path: str | Path, *, fps: float = DEFAULT_FPS, view: View = View()) -> Path:
    """Write the animation's page; returns the path."""
    path = Path(path)
    path.write_text(page(animation, fps=fps, view=view), encoding="utf-8")
    return path


def read_data(text: str) -> dict[str, Any]:
    """The animation data a page carries (the inverse of :func:`page`'s embedding)."""
    found = DATA_PATTERN.search(text)
    if found is None:
        raise ValueError("no animation data in the page")
    return json.loads(found.group(1))  # JSON reads "<\/" as "</"


__all__ = ["CONTROLS_HEIGHT", "animation_data", "page", "read_data", "write_html"]
