"""What each body looks like, derived from the model's structure.

A body declares its mass and inertia, not its shape; its outline is read
from what the system says about it:

- a planar rigid body is the convex hull of the points the system names on
  it (joint anchors, contact points, spring ends) and of their mirror
  images through its centre of mass (a box whose bottom corners touch the
  floor is the rectangle of its four corners); where those points lie on
  a line it is a rod along them, or, where its inertia is too large for a
  rod, a disc of the inertia's radius √(2 J / m); where a contact gives it a
  radius, a disc of that radius;
- a 3D rigid body is the homogeneous box of its mass and principal
  inertia (sides √(6 (J_j + J_k - J_i) / m)), turned into its principal
  axes, or the sphere a contact gives it;
- a point mass is a dot (a ball of the radius a contact gives it);
- a beam or a bar is its line of nodes (a bar with tick marks, which show
  its compression waves); a hexahedral solid is its outer faces.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .drawing import Layout

DISC_POINTS = 36
"""Points of a disc's outline."""

ROD_WIDTH = 0.05
"""A rod's drawn width, as a fraction of its length."""

BAR_TICKS = 20
"""Tick marks along a bar (at most)."""

BOX_FACES = ((0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5))
"""The six faces of a box whose vertex k has bits (x, y, z) of k selecting -/+ sides."""

HEX_FACES = ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7))
"""The six faces of a hex8 element, in its node order (:mod:`nsga_jax._elements.hex8`)."""


@dataclass
class Features:
    """What the system says about one body's shape: points named on it
    (body-frame coordinates [m]) and the radius a contact gives it at its
    centre [m] (0: none)."""

    anchors: list[np.ndarray] = field(default_factory=list)
    radius: float = 0.0


def _vector(value: Any) -> np.ndarray | None:
    """A body-frame anchor as a float vector; ``None`` for an absent one (a node or the origin)."""
    if value is None:
        return None
    a = np.asarray(value, float)
    return a.reshape(-1) if a.size else None


def body_features(model: Any) -> dict[str, Features]:
    """Each body's :class:`Features`, from the model's joints, contacts and springs."""
    from .._system import FaceContact, PlaneContact, SphereContact, SpringDamper
    from .._system.joints import AbstractTwoPointJoint

    features = {name: Features() for name in model.body_names}

    def note(body: str, at: Any, radius: Any = 0.0) -> None:
        if body not in features:
            return  # the ground
        a = _vector(at)
        if a is not None and np.any(a != 0):
            features[body].anchors.append(a)
        elif float(np.asarray(radius)) > 0:
            features[body].radius = max(features[body].radius, float(np.asarray(radius)))

    for part in (*model.joints, *model.forces):
        if isinstance(part, (AbstractTwoPointJoint, SpringDamper)):
            note(part.body_a, part.at_a)
            note(part.body_b, part.at_b)
    for contact in model.contacts:
        if isinstance(contact, PlaneContact) and contact.nodes is None:
            for row in [None] if contact.points is None else np.asarray(contact.points, float):
                note(contact.body, row, contact.radius)
        elif isinstance(contact, SphereContact):
            note(contact.body_a, contact.at_a, contact.radius_a)
            note(contact.body_b, contact.at_b, contact.radius_b)
        elif isinstance(contact, FaceContact):
            for row in np.asarray(contact.points, float):
                note(contact.body_a, row)
    return features


def convex_hull(points: np.ndarray) -> np.ndarray:
    """The convex hull (k, 2) of planar points (m, 2), counter-clockwise (Andrew's monotone chain)."""
    pts = sorted({(float(x), float(y)) for x, y in np.round(points, 12)})
    if len(pts) < 3:
        return np.asarray(pts)

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list = []
    upper: list = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.asarray(lower[:-1] + upper[:-1])


def polygon_area(xy: np.ndarray) -> float:
    """The area [m²] of a simple polygon (k, 2)."""
    if len(xy) < 3:
        return 0.0
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))


def disc(radius: float, points: int = DISC_POINTS) -> np.ndarray:
    """A disc's outline (points, 2) [m] about the origin."""
    angles = np.linspace(0.0, 2 * np.pi, points, endpoint=False)
    return radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)


def planar_outline(mass: float, inertia: float, features: Features) -> tuple[np.ndarray, bool]:
    """A planar rigid body's outline (k, 2) in its frame [m], and whether it
    is a disc (drawn with a spoke, which shows it turning); see the module."""
    if features.radius > 0:
        return disc(features.radius), True
    anchors = np.asarray(features.anchors, float).reshape(-1, 2)
    cloud = np.concatenate([anchors, -anchors, np.zeros((1, 2))])
    hull = convex_hull(cloud)
    extent = float(np.abs(cloud).max(initial=0.0))
    if extent > 0 and polygon_area(hull) > 0.05 * (2 * extent) ** 2:
        return hull, False
    wide = np.sqrt(max(2.0 * inertia / mass, 0.0))
    if extent == 0:
        return disc(wide), True
    far = cloud[np.argmax(np.linalg.norm(cloud, axis=1))]
    along = far / np.linalg.norm(far)
    across = np.array([-along[1], along[0]])
    length = 2.0 * float(np.abs(cloud @ along).max())
    width_squared = 12.0 * inertia / mass - length**2  # a rectangle's J = m (L² + w²) / 12
    if width_squared > (0.5 * length) ** 2:  # too much inertia for a rod: the disc of its inertia
        return disc(wide), True
    width = max(np.sqrt(max(width_squared, 0.0)), ROD_WIDTH * length, float(np.abs(cloud @ across).max()) * 2)
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float)
    return (corners[:, :1] * 0.5 * length * along + corners[:, 1:] * 0.5 * width * across), False


def inertia_box(mass: float, inertia: np.ndarray) -> np.ndarray:
    """The vertices (8, 3) [m], in the body frame, of the homogeneous box
    with this mass [kg] and inertia tensor (3, 3) [kg m²], along its
    principal axes; vertex k has bits (x, y, z) of k selecting -/+ sides."""
    moments, axes = np.linalg.eigh(np.asarray(inertia, float))
    total = moments.sum()
    sides = np.sqrt(np.maximum(6.0 * (total - 2.0 * moments) / mass, 0.0))
    signs = np.array([[(k >> i) & 1 for i in range(3)] for k in range(8)], float) * 2 - 1
    return (0.5 * signs * sides) @ axes.T


def hex_outer_faces(connectivity: np.ndarray) -> list[tuple[int, ...]]:
    """The faces (4 node numbers each) of a hex8 mesh that belong to one element only: its outer surface."""
    count: dict[tuple[int, ...], int] = {}
    faces: dict[tuple[int, ...], tuple[int, ...]] = {}
    for element in np.asarray(connectivity):
        for face in HEX_FACES:
            nodes = tuple(int(element[i]) for i in face)
            key = tuple(sorted(nodes))
            count[key] = count.get(key, 0) + 1
            faces[key] = nodes
    return [faces[key] for key, c in count.items() if c == 1]


def add_body(layout: Layout, name: str, body: Any, features: Features, material: Any) -> None:
    """Add the items that draw body ``name``; ``material(name, at=None,
    node=None, offset=None) -> PointFn`` makes its point functions."""
    from .._system import Bar, HexSolid, RigidBody2D, RigidBody3D

    part = f"bodies.{name}"
    if isinstance(body, RigidBody2D):
        outline, round_ = planar_outline(float(body.mass_), float(body.inertia), features)
        ring = [layout.point(material(name, at=xy)) for xy in outline]
        layout.item("body", "polygon", ring, part=part)
        if round_:
            centre = layout.point(material(name, at=np.zeros(2)))
            layout.item("spoke", "line", [centre, ring[0]], part=part)
    elif isinstance(body, RigidBody3D):
        if features.radius > 0:
            layout.item("ball", "dot", [layout.point(material(name, at=np.zeros(3)))], radius=features.radius,
                        part=part)
            return
        corners = [layout.point(material(name, at=xyz)) for xyz in inertia_box(float(body.mass_),
                                                                                np.asarray(body.inertia))]
        for face in BOX_FACES:
            layout.item("body", "polygon", [corners[i] for i in face], part=part)
    elif isinstance(body, HexSolid):
        outer = hex_outer_faces(body.connectivity.array)
        index = {n: layout.point(material(name, node=n)) for n in sorted({n for quad in outer for n in quad})}
        for quad in outer:
            layout.item("solid", "polygon", [index[n] for n in quad], part=part)
    elif isinstance(body, Bar):
        _add_bar(layout, name, body, material)
    elif body.has_nodes:  # a beam, or any body of nodes
        nodes = [layout.point(material(name, node=i)) for i in range(body.n_nodes)]
        layout.item("beam", "line", nodes, part=part)
    else:  # a point mass, or any body drawn at its origin
        at = np.zeros(body.dim)
        layout.item("ball", "dot", [layout.point(material(name, at=at))], radius=features.radius, part=part)


def _add_bar(layout: Layout, name: str, body: Any, material: Any) -> None:
    """A bar: its line of nodes, and tick marks across it at evenly spaced nodes."""
    part = f"bodies.{name}"
    n = body.n_nodes
    nodes = [layout.point(material(name, node=i)) for i in range(n)]
    layout.item("bar", "line", nodes, part=part)
    line = layout.line if layout.line is not None else np.array([1.0, 0.0, 0.0])
    across = np.array([-line[1], line[0], 0.0])  # in the drawing's plane
    half = 0.015 * float(np.asarray(body.length))
    ticks: list[int] = []
    for i in sorted(set(np.linspace(0, n - 1, min(BAR_TICKS, n)).round().astype(int).tolist())):
        ticks += [layout.point(material(name, node=i, offset=-half * across)),
                  layout.point(material(name, node=i, offset=half * across))]
    layout.item("tick", "segments", ticks, part=part)


__all__ = ["Features", "add_body", "body_features", "convex_hull", "hex_outer_faces", "inertia_box",
           "planar_outline"]
