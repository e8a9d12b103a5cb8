"""The vocabulary of a drawing: what is drawn (:class:`Item`), which points
it follows (functions of the coordinates), and the fixed planes a system
touches.

A drawing lives in 3D world coordinates [m]. A planar system is drawn in its
plane (x to the right, y up, z = 0); a system on a line is drawn along x, or
along y (up) where gravity acts along the line.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

PointFn = Callable[..., object]
"""``f(q) -> (3,)``: a world point [m] (or a unit direction) as a JAX
function of the global coordinates q (n,)."""

KINDS = ("ground", "hatch", "grid", "guide", "shadow", "body", "solid", "ball", "spoke", "beam", "bar", "tick", "rod",
         "spring", "joint", "pivot", "contact", "force")
"""What an item is, which decides its colours and its layer (:mod:`~nsga_jax._animate.screen`):
``ground``/``hatch``/``grid`` a fixed plane (its line or patch, hatching,
floor grid); ``guide`` a slider's fixed line; ``shadow`` a body's shadow
on a floor (3D); ``body`` a rigid body's outline;
``solid`` an outer face of a hexahedral solid; ``ball`` a point mass or a
sphere; ``spoke`` a line that shows a disc turning; ``beam``/``bar`` a
flexible body's centre line; ``tick`` marks along a bar; ``rod`` a distance
joint; ``spring`` a spring–damper; ``joint``/``pivot`` a joint between bodies
/ to the ground; ``contact`` a contact point while it touches; ``force`` a
contact force arrow."""

SHAPES = ("polygon", "line", "segments", "dot", "arrow", "spring")
"""How an item is drawn from its points: a closed filled polygon, an open
polyline, disjoint segments (pairs of points), a dot per point (of world
radius ``radius``, or a marker), an arrow (tail, head), a spring's zigzag
(two ends)."""


@dataclass(frozen=True)
class Item:
    """One thing drawn.

    Attributes:
        kind: what it is (:data:`KINDS`).
        shape: how it is drawn (:data:`SHAPES`).
        points: indices of its points in a frame's point array.
        radius: a dot's world radius [m]; 0 draws a marker of the kind's size.
        part: the part it draws (``"bodies.box1"``, ``"contacts.floor"``, ...).
    """

    kind: str
    shape: str
    points: tuple[int, ...]
    radius: float = 0.0
    part: str = ""


@dataclass(frozen=True)
class Plane:
    """A fixed plane (a line in a planar drawing): through ``origin`` (3,)
    [m] with unit ``normal`` (3,) towards the admissible side. ``kind``
    ``ground`` is a contact's obstacle (hatched on its solid side), ``guide``
    a slider's line (``normal`` across it)."""

    origin: np.ndarray
    normal: np.ndarray
    kind: str = "ground"
    part: str = ""


@dataclass(frozen=True)
class ContactMark:
    """A unilateral constraint row drawn as a contact point.

    Attributes:
        row: its index among the unilateral constraints (a column of the
            run's gaps; the impulse column is ``n_bilateral + row``).
        point: index of the contact point.
        normal: index of its unit normal (the direction of the force it
            exerts) among the layout's normals.
        item: index of its ``contact`` item.
    """

    row: int
    point: int
    normal: int
    item: int


@dataclass
class Layout:
    """A system's drawing before it moves: the point functions, the items
    drawn from them, the fixed planes and the contact points.

    Attributes:
        dim: 2 (drawn in the plane) or 3 (in space).
        up: the world's up (3,), unit: against gravity (z where there is none in 3D, y in the plane).
        points: the point functions (see :data:`PointFn`).
        normals: functions giving the contacts' unit normals (3,).
        items, planes, contacts: see :class:`Item`, :class:`Plane`, :class:`ContactMark`.
        line: the direction (3,) a system on a line is drawn along (``None`` in 2D and 3D).
    """

    dim: int
    up: np.ndarray
    line: np.ndarray | None = None
    points: list[PointFn] = field(default_factory=list)
    normals: list[PointFn] = field(default_factory=list)
    items: list[Item] = field(default_factory=list)
    planes: list[Plane] = field(default_factory=list)
    contacts: list[ContactMark] = field(default_factory=list)

    def point(self, fn: PointFn) -> int:
        """Add a point function; returns its index."""
        self.points.append(fn)
        return len(self.points) - 1

    def item(self, kind: str, shape: str, points: list[int] | tuple[int, ...], *, radius: float = 0.0,
             part: str = "") -> int:
        """Add an item; returns its index."""
        assert kind in KINDS and shape in SHAPES, (kind, shape)
        self.items.append(Item(kind, shape, tuple(points), float(radius), part))
        return len(self.items) - 1

    def plane(self, origin: np.ndarray, normal: np.ndarray, kind: str = "ground", part: str = "") -> None:
        """Add a fixed plane, once: a plane already there (an obstacle that
        several contacts share, as a floor does) is not added again."""
        n = np.asarray(normal, float) / np.linalg.norm(normal)
        o = np.asarray(origin, float)
        for other in self.planes:
            if other.kind == kind and abs(float(other.normal @ n)) > 1 - 1e-9 and abs(float(n @ (o - other.origin))) \
                    <= 1e-9 * max(1.0, float(np.abs(o).max())):
                return
        self.planes.append(Plane(o, n, kind, part))


__all__ = ["KINDS", "SHAPES", "ContactMark", "Item", "Layout", "Plane", "PointFn"]
