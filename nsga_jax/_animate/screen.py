"""From world to pixels: the view (a planar drawing as it is, a 3D one in
a fixed oblique projection that turns about the world's up), the fit of
what moves into the picture, and each frame's shapes in drawing order,
with their colours.

The HTML player (``player.js``) implements the same view, fit, order and
colours (:data:`STYLES` travels with its data), so that a GIF frame and the
page at the same frame show the same picture.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .frames import Animation, drawing_size


@dataclass(frozen=True)
class Style:
    """How a kind of item looks: its ``layer`` (lower layers are drawn
    first), whether a 3D drawing draws its items back to front
    (``by_depth``), ``fill`` and ``stroke`` colours (``""``: none), line
    ``width`` [px] and a dot's ``marker`` radius [px] where it has no world radius."""

    layer: int
    fill: str = ""
    stroke: str = ""
    width: float = 1.0
    marker: float = 0.0
    by_depth: bool = False


STYLES: dict[str, Style] = {
    "ground": Style(0, "#e6e1d3", "#6b6558", 2.0),
    "hatch": Style(0, "", "#9a9384", 1.0),
    "grid": Style(0, "", "#c9c2b0", 1.0),
    "guide": Style(0, "", "#8a8a8a", 1.5),
    "shadow": Style(1, "#c4bdab", "", 0.0),
    "body": Style(2, "#4f81bd", "#1f3f66", 1.5, by_depth=True),
    "solid": Style(2, "#5b9bd5", "#2e5c8a", 0.8, by_depth=True),
    "ball": Style(2, "#4f81bd", "#1f3f66", 1.5, 8.0, by_depth=True),
    "spoke": Style(3, "", "#1f3f66", 1.5),
    "beam": Style(3, "", "#c0504d", 4.0),
    "bar": Style(3, "", "#c0504d", 5.0),
    "tick": Style(3, "", "#7f2a28", 1.5),
    "rod": Style(3, "", "#404040", 2.5),
    "spring": Style(3, "", "#8064a2", 1.5),
    "joint": Style(4, "#ffffff", "#202020", 1.5, 4.0),
    "pivot": Style(4, "#202020", "#202020", 1.0, 4.5),
    "contact": Style(5, "#e03c31", "#8b1a12", 1.0, 3.5),
    "force": Style(6, "#e08a00", "#e08a00", 2.0),
}
"""Every kind's look (:data:`~nsga_jax._animate.drawing.KINDS`)."""

MARGIN = 24.0
"""Free border around the fitted drawing [px]."""

TITLE_BAND = 28.0
"""Height of the band at the top kept for the title and the time [px]."""

SPRING_COILS = 8
"""Zigzags of a drawn spring."""


@dataclass(frozen=True)
class View:
    """A picture of ``width`` × ``height`` pixels; a 3D drawing seen from
    ``azimuth`` [rad] about the up axis and ``elevation`` [rad] above the
    horizontal (orthographic)."""

    width: int = 640
    height: int = 480
    azimuth: float = math.radians(-60.0)
    elevation: float = math.radians(25.0)


def camera(up: np.ndarray, view: View) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(right, screen_up, toward)``, unit vectors (3,) of the world: the
    picture's x and y axes and the direction towards the viewer."""
    up = np.asarray(up, float) / np.linalg.norm(up)
    helper = np.eye(3)[0] if abs(up[0]) < 0.9 else np.eye(3)[1]
    h1 = helper - up * (helper @ up)
    h1 /= np.linalg.norm(h1)
    h2 = np.cross(up, h1)
    ce, se = math.cos(view.elevation), math.sin(view.elevation)
    toward = ce * (math.cos(view.azimuth) * h1 + math.sin(view.azimuth) * h2) + se * up
    right = np.cross(up, toward)
    right /= np.linalg.norm(right)
    return right, np.cross(toward, right), toward


def project(points: np.ndarray, animation: Animation, view: View) -> tuple[np.ndarray, np.ndarray]:
    """Picture coordinates (..., 2) [m] and depth (..., ) [m] (larger: nearer) of world points (..., 3)."""
    points = np.asarray(points, float)
    if animation.dim == 2:
        return points[..., :2], np.zeros(points.shape[:-1])
    right, screen_up, toward = camera(animation.up, view)
    return np.stack([points @ right, points @ screen_up], axis=-1), points @ toward


@dataclass(frozen=True)
class Fit:
    """World picture coordinates to pixels: ``pixel = centre_px + scale (x - centre) * (1, -1)``."""

    scale: float
    centre: np.ndarray
    centre_px: np.ndarray

    def pixels(self, xy: np.ndarray) -> np.ndarray:
        """Pixel coordinates (..., 2) (y downward) of picture coordinates (..., 2) [m]."""
        return self.centre_px + self.scale * (np.asarray(xy) - self.centre) * np.array([1.0, -1.0])


def fit(animation: Animation, view: View) -> Fit:
    """The scale and centre that frame :attr:`Animation.focus` (its corners,
    projected) in the picture below the title band, the same in x and y."""
    low, high = animation.focus
    corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])
    xy, _ = project(corners, animation, view)
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    floor = 1e-3 * drawing_size(animation.focus)
    spans = np.maximum(hi - lo, floor)
    available = np.array([view.width - 2 * MARGIN, view.height - TITLE_BAND - 2 * MARGIN])
    scale = float(np.min(available / spans))
    centre_px = np.array([view.width / 2, TITLE_BAND + MARGIN + available[1] / 2])
    return Fit(scale, 0.5 * (lo + hi), centre_px)


@dataclass(frozen=True)
class Shape:
    """One primitive to draw, in pixels: a ``polygon`` (filled and stroked),
    a ``line`` (polyline), ``segments`` (pairs) or a ``circle`` (centre
    ``xy[0]``, ``radius`` [px])."""

    kind: str
    shape: str
    xy: np.ndarray
    fill: str
    stroke: str
    width: float
    radius: float = 0.0


def shade(colour: str, factor: float) -> str:
    """``colour`` (``#rrggbb``) with its channels scaled by ``factor`` (clipped to 0..255)."""
    rgb = [int(colour[i:i + 2], 16) for i in (1, 3, 5)]
    return "#" + "".join(f"{min(255, max(0, round(c * factor))):02x}" for c in rgb)


def light_direction(animation: Animation, view: View) -> np.ndarray:
    """The unit direction (3,) towards the light: above and behind the viewer."""
    right, screen_up, toward = camera(animation.up, view)
    light = toward + 0.6 * screen_up + 0.3 * right
    return light / np.linalg.norm(light)


def face_light(points: np.ndarray, light: np.ndarray) -> float:
    """A 3D face's brightness factor, 0.55 ... 1: how squarely it faces the
    unit ``light`` (3,) (Newell's normal of its points (k, 3))."""
    nxt = np.roll(points, -1, axis=0)
    normal = np.array([np.sum((points[:, 1] - nxt[:, 1]) * (points[:, 2] + nxt[:, 2])),
                       np.sum((points[:, 2] - nxt[:, 2]) * (points[:, 0] + nxt[:, 0])),
                       np.sum((points[:, 0] - nxt[:, 0]) * (points[:, 1] + nxt[:, 1]))])
    length = float(np.sqrt(normal @ normal))
    if length == 0:
        return 1.0
    return 0.55 + 0.45 * abs(float(normal @ light)) / length


def arrow_shapes(kind: str, style: Style, tail: np.ndarray, head: np.ndarray) -> list[Shape]:
    """An arrow's shaft and head (a triangle of 10 px, or less on a short arrow)."""
    d = head - tail
    length = float(np.linalg.norm(d))
    if length < 1.0:
        return []
    u = d / length
    n = np.array([-u[1], u[0]])
    tip = min(10.0, 0.5 * length)
    base = head - tip * u
    triangle = np.stack([head, base + 0.45 * tip * n, base - 0.45 * tip * n])
    return [Shape(kind, "line", np.stack([tail, base]), "", style.stroke, style.width),
            Shape(kind, "polygon", triangle, style.fill, style.stroke, 1.0)]


def spring_line(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A spring's zigzag (pixels) between its ends: straight ends, then
    :data:`SPRING_COILS` zigzags of 5 px amplitude."""
    d = b - a
    length = float(np.linalg.norm(d))
    if length < 1e-9:
        return np.stack([a, b])
    u = d / length
    n = np.array([-u[1], u[0]])
    steps = 2 * SPRING_COILS
    s = np.linspace(0.15, 0.85, steps + 1)
    side = np.where(np.arange(steps + 1) % 2 == 1, 1.0, -1.0) * 5.0
    side[0] = side[-1] = 0.0
    middle = a + np.outer(s * length, u) + np.outer(side, n)
    return np.concatenate([a[None], middle, b[None]])


def frame_shapes(animation: Animation, frame: int, view: View, fitted: Fit) -> list[Shape]:
    """Frame ``frame``'s shapes in drawing order (layers; within a layer drawn
    ``by_depth``, a 3D drawing from back to front), hidden items left out."""
    world = animation.frame_points(frame)
    xy, depth = project(world, animation, view)
    light = light_direction(animation, view)
    px = fitted.pixels(xy)
    keyed: list[tuple[int, float, int, list[Shape]]] = []
    for index, item in enumerate(animation.items):
        if not animation.active[frame, index]:
            continue
        style = STYLES[item.kind]
        pts = px[list(item.points)]
        fill = style.fill
        if item.shape == "polygon":
            if animation.dim == 3 and item.kind in ("body", "solid"):
                fill = shade(fill, face_light(world[list(item.points)], light))
            shapes = [Shape(item.kind, "polygon", pts, fill, style.stroke, style.width)]
        elif item.shape == "dot":
            radius = item.radius * fitted.scale if item.radius > 0 else style.marker
            shapes = [Shape(item.kind, "circle", p[None], fill, style.stroke, style.width, radius) for p in pts]
        elif item.shape == "arrow":
            shapes = arrow_shapes(item.kind, style, pts[0], pts[1])
        elif item.shape == "spring":
            shapes = [Shape(item.kind, "line", spring_line(pts[0], pts[1]), "", style.stroke, style.width)]
        else:
            shapes = [Shape(item.kind, item.shape, pts, "", style.stroke, style.width)]
        nearness = float(np.mean(depth[list(item.points)])) if animation.dim == 3 and style.by_depth else 0.0
        keyed.append((style.layer, nearness, index, shapes))
    keyed.sort(key=lambda k: (k[0], k[1], k[2]))  # far faces first
    return [shape for *_, shapes in keyed for shape in shapes]


def styles_table() -> dict[str, dict[str, object]]:
    """:data:`STYLES` as plain data (for the HTML player)."""
    return {kind: asdict(style) for kind, style in STYLES.items()}


__all__ = ["Fit", "STYLES", "Shape", "Style", "View", "camera", "fit", "frame_shapes", "project", "shade",
           "styles_table"]
