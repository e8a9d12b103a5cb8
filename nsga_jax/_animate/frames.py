"""A run's drawing frame by frame: every item's points at the recorded
times, which contacts touch, the fixed planes spanned around what moves, and
(optionally) the contact forces as arrows.

A long run is subsampled to at most ``max_frames`` evenly spaced records
(records of failed steps that hold NaN are left out);
what happens between two frames is not lost: a contact is shown touching,
and its force arrow drawn with the largest force, if it touched at any step
recorded since the previous frame (an impact lasts one step).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._results import ConfigError
from .drawing import Item, Layout, Plane
from .run_folder import RecordedRun

DEFAULT_MAX_FRAMES = 120
"""Frames of an animation at most, by default (a long run is subsampled)."""

TOUCH = 1e-4
"""A contact touches where its gap is below this fraction of the drawing's size (or its impulse is positive)."""

FORCE_LENGTH = 0.25
"""A typical contact force (the 90th percentile of those drawn) is an arrow of this fraction of the drawing's size."""

LONGEST_ARROW = 0.6
"""No arrow is longer than this fraction of the drawing's size (impacts are clipped to it)."""


@dataclass(frozen=True)
class Animation:
    """What an animation draws, frame by frame, in world coordinates [m].

    Attributes:
        title: what it shows (the scene's name).
        dim: 2 (drawn in the plane: x right, y up) or 3 (in space).
        up: the world's up (3,), unit (3D views turn about it).
        items: what is drawn (:class:`~nsga_jax._animate.drawing.Item`); an
            item's point index ``i`` is ``moving[:, i]`` for ``i < P``, else
            ``fixed[i - P]``.
        times: the frames' times (F,) [s].
        moving: the points that move (F, P, 3) [m].
        fixed: the points that do not (S, 3) [m] (planes, guides).
        active: (F, I): whether each item shows in each frame (contact points
            while they touch, force arrows while they push; the others always).
        focus: the box (2, 3) [m] (lower and upper corners) around everything
            that moves over the whole run: what a view frames.
    """

    title: str
    dim: int
    up: np.ndarray
    items: tuple[Item, ...]
    times: np.ndarray
    moving: np.ndarray
    fixed: np.ndarray
    active: np.ndarray
    focus: np.ndarray

    @property
    def n_frames(self) -> int:
        return int(self.times.shape[0])

    def frame_points(self, frame: int) -> np.ndarray:
        """Every point (P + S, 3) [m] of frame ``frame``."""
        return np.concatenate([self.moving[frame], self.fixed])

    @property
    def size(self) -> float:
        """The drawing's size [m]: the largest side of :attr:`focus`."""
        return drawing_size(self.focus)


def drawing_size(focus: np.ndarray) -> float:
    """The largest side [m] of a box (2, 3); 1 m for a box of no size."""
    side = float(np.max(focus[1] - focus[0]))
    return side if side > 0 else 1.0


def frame_rows(rows: int, max_frames: int) -> np.ndarray:
    """Indices of at most ``max_frames`` evenly spaced records of ``rows``, the first and the last included."""
    count = max(1, min(rows, max_frames))
    return np.unique(np.round(np.linspace(0, rows - 1, count)).astype(int))


def evaluate(functions: list[Any], q: np.ndarray) -> np.ndarray:
    """The point functions at every row of ``q`` (F, n): (F, len(functions), 3),
    vectorised over the rows (``vmap``; not compiled as one program, whose
    compilation would cost seconds for a mesh's hundreds of points)."""
    if not functions:
        return np.zeros((q.shape[0], 0, 3))
    import jax
    import jax.numpy as jnp

    stacked = jax.vmap(lambda x: jnp.stack([fn(x) for fn in functions]))
    return np.asarray(stacked(jnp.asarray(q)), float)


def window_starts(rows: np.ndarray) -> np.ndarray:
    """First record of each frame's window: frame k covers the records after frame k - 1 up to its own."""
    return np.concatenate([[0], rows[:-1] + 1]).astype(int)


def _focus(layout: Layout, moving: np.ndarray) -> np.ndarray:
    """The box around every moving point (dots grown by their radius) and the
    nearest point of each plane."""
    low, high = moving.min(axis=(0, 1)), moving.max(axis=(0, 1))
    for item in layout.items:
        if item.shape == "dot" and item.radius > 0:
            centres = moving[:, list(item.points)]
            low = np.minimum(low, centres.min(axis=(0, 1)) - item.radius)
            high = np.maximum(high, centres.max(axis=(0, 1)) + item.radius)
    centre = 0.5 * (low + high)
    for plane in layout.planes:
        foot = centre - plane.normal * float(plane.normal @ (centre - plane.origin))
        low, high = np.minimum(low, foot), np.maximum(high, foot)
    if layout.dim == 2:
        low[2] = high[2] = 0.0
    return np.stack([low, high])


def plane_drawing(plane: Plane, focus: np.ndarray, dim: int) -> list[tuple[str, str, np.ndarray]]:
    """A plane's ``(kind, shape, points)`` items, spanned around the focus:
    in the plane a long line (hatched on an obstacle's solid side), in space
    a square patch with a grid."""
    size = drawing_size(focus)
    centre = 0.5 * (focus[0] + focus[1])
    foot = centre - plane.normal * float(plane.normal @ (centre - plane.origin))
    n = plane.normal
    if dim == 2:
        along = np.array([-n[1], n[0], 0.0])
        reach = 5.0 * size
        out = [(plane.kind, "line", np.stack([foot - reach * along, foot + reach * along]))]
        if plane.kind == "ground":
            marks = foot + np.outer(np.arange(-reach, reach, size / 20.0), along)
            into = 0.035 * size * (np.sqrt(0.5) * (along - n))
            out.append(("hatch", "segments", np.stack([marks, marks + into], axis=1).reshape(-1, 3)))
        return out
    helper = np.eye(3)[int(np.argmin(np.abs(n)))]
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    half = 1.2 * size
    corners = np.array([foot + half * (a * t1 + b * t2) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    ticks = np.linspace(-half, half, 11)
    lines = [foot + half * s * t1 + k * t2 for k in ticks for s in (-1, 1)]
    lines += [foot + k * t1 + half * s * t2 for k in ticks for s in (-1, 1)]
    return [(plane.kind, "polygon", corners), ("grid", "segments", np.asarray(lines))]


def _shadows(layout: Layout, moving: np.ndarray) -> tuple[np.ndarray, list[Item]]:
    """Shadows on the floors of a 3D drawing (planes facing up): each body's
    and solid's faces, and each ball, projected along the up axis onto every
    floor; their points (F, k, 3) [m] and items (point indices from
    ``moving.shape[1]`` on). A shadow tells how high a body flies."""
    floors = [plane for plane in layout.planes if plane.kind == "ground" and float(plane.normal @ layout.up) > 0.5]
    casting = [item for item in layout.items if item.kind in ("body", "solid", "ball")]
    if layout.dim != 3 or not floors or not casting:
        return np.zeros((moving.shape[0], 0, 3)), []
    sources = sorted({i for item in casting for i in item.points})
    points: list[np.ndarray] = []
    items: list[Item] = []
    for plane in floors:
        first = moving.shape[1] + sum(p.shape[1] for p in points)
        index = {i: first + k for k, i in enumerate(sources)}
        height = (moving[:, sources] - plane.origin) @ plane.normal / float(plane.normal @ layout.up)
        points.append(moving[:, sources] - height[..., None] * layout.up)
        items += [Item("shadow", item.shape, tuple(index[i] for i in item.points), item.radius, item.part)
                  for item in casting]
    return np.concatenate(points, axis=1), items


def _force_arrows(run: RecordedRun, layout: Layout, moving: np.ndarray, normals: np.ndarray, pushes: np.ndarray,
                  size: float) -> tuple[np.ndarray, np.ndarray]:
    """Tails and heads (F, C, 2, 3) of the contact force arrows and where they
    show (F, C): each contact's largest normal force Λ / h [N] over the frame's
    window, along its normal, scaled to the drawing."""
    force = np.stack([pushes[:, mark.row] for mark in layout.contacts], axis=1) / run.h  # (F, C) [N]
    positive = force[force > 0]
    scale = FORCE_LENGTH * size / float(np.percentile(positive, 90)) if positive.size else 0.0
    length = np.minimum(force * scale, LONGEST_ARROW * size)
    tails = np.stack([moving[:, mark.point] for mark in layout.contacts], axis=1)
    heads = tails + np.stack([normals[:, mark.normal] for mark in layout.contacts], axis=1) * length[..., None]
    return np.stack([tails, heads], axis=2), force > 0


def animation_of(run: RecordedRun, *, max_frames: int = DEFAULT_MAX_FRAMES, forces: bool = False) -> Animation:
    """The animation of a recorded run: at most ``max_frames`` frames, with
    contact force arrows where ``forces``."""
    from .parts import layout_of  # loads JAX

    layout = layout_of(run.model)
    finite = np.flatnonzero(np.all(np.isfinite(run.q), axis=1))  # a failed step's record may hold NaN
    if finite.size == 0:
        raise ConfigError(f"run folder {str(run.folder)!r}: no recorded step has finite coordinates; nothing to draw")
    rows = finite[frame_rows(finite.size, max_frames)]
    moving = evaluate(layout.points, run.q[rows])
    normals = evaluate(layout.normals, run.q[rows])
    starts = window_starts(rows)
    end = int(rows[-1]) + 1
    nb = run.model.n_bilateral
    nu = run.gap.shape[1]
    gaps = np.nan_to_num(run.gap[:end], nan=np.inf)  # a failed step's NaN: neither touching nor pushing
    impulses = np.maximum(np.nan_to_num(run.impulse[:end, nb:nb + nu], nan=0.0, posinf=0.0), 0.0)
    closest = np.minimum.reduceat(gaps, starts, axis=0) if nu else np.zeros((len(rows), 0))
    pushes = np.maximum.reduceat(impulses, starts, axis=0) if nu else np.zeros((len(rows), 0))
    focus = _focus(layout, moving)
    size = drawing_size(focus)
    items = list(layout.items)
    active = np.ones((len(rows), len(items)), bool)
    for mark in layout.contacts:
        active[:, mark.item] = (closest[:, mark.row] <= TOUCH * size) | (pushes[:, mark.row] > 0)
    if forces and layout.contacts:
        arrows, shown = _force_arrows(run, layout, moving, normals, pushes, size)
        first = moving.shape[1]
        moving = np.concatenate([moving, arrows.reshape(len(rows), -1, 3)], axis=1)
        for c, mark in enumerate(layout.contacts):
            items.append(Item("force", "arrow", (first + 2 * c, first + 2 * c + 1), part=items[mark.item].part))
        active = np.concatenate([active, shown], axis=1)
    shadow_points, shadow_items = _shadows(layout, moving)
    moving = np.concatenate([moving, shadow_points], axis=1)
    items += shadow_items
    fixed: list[np.ndarray] = []
    offset = moving.shape[1]
    for plane in layout.planes:
        for kind, shape, points in plane_drawing(plane, focus, layout.dim):
            indices = tuple(range(offset, offset + len(points)))
            items.append(Item(kind, shape, indices, part=plane.part))
            fixed.append(points)
            offset += len(points)
    active = np.concatenate([active, np.ones((len(rows), len(items) - active.shape[1]), bool)], axis=1)
    fixed_points = np.concatenate(fixed) if fixed else np.zeros((0, 3))
    return Animation(run.name, layout.dim, layout.up, tuple(items), run.times[rows], moving, fixed_points, active,
                     focus)


__all__ = ["Animation", "DEFAULT_MAX_FRAMES", "animation_of", "drawing_size", "frame_rows", "plane_drawing"]
