"""A system's drawing, part by part: its bodies (:mod:`~nsga_jax._animate.outlines`),
joints, contacts (their obstacles and contact points) and springs, each a
set of items following material points of the bodies.

Every point is a JAX function of the global coordinates, built on the
bodies' own :meth:`~nsga_jax.system.AbstractBody.position`, so that a drawing
moves exactly as the model's constraints see it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .._system import Distance, FaceContact, Gravity, PlaneContact, Slider, SphereContact, SpringDamper
from .._system.base import GROUND, anchor, point
from .._system.contacts import node_indices
from .._system.joints import AbstractTwoPointJoint
from .drawing import ContactMark, Layout, PointFn
from .outlines import add_body, body_features


def gravity_of(model: Any) -> np.ndarray | None:
    """The system's uniform acceleration (dim,) [m/s²] (the sum of its gravity parts), or ``None``."""
    total = None
    for force in model.forces:
        if isinstance(force, Gravity):
            g = np.asarray(force.acceleration, float)
            total = g if total is None else total + g
    return total if total is not None and np.any(total != 0) else None


def orientation(model: Any) -> tuple[np.ndarray, np.ndarray | None]:
    """``(up, line)``: the drawing's up (3,) and, for a system on a line, the
    direction (3,) it is drawn along: up against gravity where it acts
    along the line, else across the page (see :mod:`~nsga_jax._animate.drawing`)."""
    g = gravity_of(model)
    if model.dim == 3:
        return (np.array([0.0, 0.0, 1.0]) if g is None else -g / np.linalg.norm(g)), None
    up = np.array([0.0, 1.0, 0.0])
    if model.dim == 2:
        return up, None
    return up, (np.array([1.0, 0.0, 0.0]) if g is None else -np.sign(g[0]) * up)


def embed_array(x: Any, dim: int, line: np.ndarray | None) -> np.ndarray:
    """A point or direction of the system's space (dim,) in the drawing's 3D world (3,)."""
    x = np.asarray(x, float).reshape(-1)
    if dim == 3:
        return x
    if dim == 2:
        return np.concatenate([x, [0.0]])
    assert line is not None
    return x[0] * line


def material_points(model: Any, line: np.ndarray | None) -> Callable[..., PointFn]:
    """``material(body, at=None, node=None, offset=None) -> PointFn``: the
    function of a material point of a body (``"ground"``: a fixed world
    point), shifted by ``offset`` (3,) [m] in the drawing."""
    import jax.numpy as jnp

    dim = model.dim
    direction = None if line is None else jnp.asarray(line)

    def embed(x):
        if dim == 3:
            return x
        if dim == 2:
            return jnp.concatenate([x, jnp.zeros((1,), x.dtype)])
        return x[0] * direction.astype(x.dtype)

    def material(body_name: str, at: Any = None, node: int | None = None, offset: Any = None) -> PointFn:
        body = model.body(body_name)
        cols = model.coordinates(body_name)
        local = anchor(None if at is None or np.size(at) == 0 else np.asarray(at, float))
        shift = None if offset is None else jnp.asarray(offset, float)

        def fn(q):
            x = embed(point(body, q[cols], local.astype(q.dtype), node))
            return x if shift is None else x + shift.astype(q.dtype)

        return fn

    return material


def layout_of(model: Any) -> Layout:
    """The drawing of a :class:`~nsga_jax.system.SystemModel`: its bodies,
    joints, contacts and springs."""
    up, line = orientation(model)
    layout = Layout(dim=3 if model.dim == 3 else 2, up=up, line=line)
    material = material_points(model, line)
    features = body_features(model)
    for name, body in zip(model.body_names, model.bodies):
        add_body(layout, name, body, features[name], material)
    for name, joint in zip(model.joint_names, model.joints):
        _add_joint(layout, model, f"joints.{name}", joint, material, line)
    for name, contact in zip(model.contact_names, model.contacts):
        first = model.rows("contacts", name).start - model.n_bilateral
        _add_contact(layout, model, f"contacts.{name}", contact, first, material, line)
    for name, force in zip(model.force_names, model.forces):
        if isinstance(force, SpringDamper):
            ends = [layout.point(material(force.body_a, force.at_a, force.node_a)),
                    layout.point(material(force.body_b, force.at_b, force.node_b))]
            layout.item("spring", "spring", ends, part=f"forces.{name}")
    return layout


def _add_joint(layout: Layout, model: Any, part: str, joint: Any, material: Any, line: np.ndarray | None) -> None:
    """A joint's marker at its anchor (``pivot`` on the ground); a distance
    joint's rod between its anchors; a slider's guide line."""
    if not isinstance(joint, AbstractTwoPointJoint):
        return  # a joint of a kind this drawing does not know: not drawn
    a = layout.point(material(joint.body_a, joint.at_a, joint.node_a))
    b = layout.point(material(joint.body_b, joint.at_b, joint.node_b))
    if isinstance(joint, Distance):  # a rod, and a pivot where it holds to the ground
        layout.item("rod", "line", [a, b], part=part)
        for body, end in ((joint.body_a, a), (joint.body_b, b)):
            if body == GROUND:
                layout.item("pivot", "dot", [end], part=part)
    elif isinstance(joint, Slider):
        if joint.body_a == GROUND:  # a slider is planar: its guide is a line of the plane
            axis = np.asarray(joint.axis, float)
            at = np.asarray(joint.at_a, float) if np.size(joint.at_a) else np.zeros(2)
            layout.plane(np.array([at[0], at[1], 0.0]), np.array([-axis[1], axis[0], 0.0]), kind="guide", part=part)
        layout.item("joint", "dot", [b], part=part)
    else:
        on_ground = joint.body_a == GROUND or joint.body_b == GROUND
        layout.item("pivot" if on_ground else "joint", "dot", [b if joint.body_a == GROUND else a], part=part)


def _constant(vector: np.ndarray) -> PointFn:
    import jax.numpy as jnp

    def fn(q):
        return jnp.asarray(vector, q.dtype)

    return fn


def _contact_points(layout: Layout, part: str, first: int, normal: int, points: list[PointFn]) -> None:
    for i, fn in enumerate(points):
        index = layout.point(fn)
        item = layout.item("contact", "dot", [index], part=part)
        layout.contacts.append(ContactMark(first + i, index, normal, item))


def _add_contact(layout: Layout, model: Any, part: str, contact: Any, first: int, material: Any,
                 line: np.ndarray | None) -> None:
    """A contact's obstacle (a plane contact's plane) and its contact points,
    each with the normal along which its force acts."""
    import jax.numpy as jnp

    dim = model.dim
    if isinstance(contact, PlaneContact):
        n = embed_array(np.asarray(contact.normal) / np.linalg.norm(contact.normal), dim, line)
        layout.plane(embed_array(contact.origin, dim, line), n, part=part)
        layout.normals.append(_constant(n))
        offset = -float(np.asarray(contact.radius)) * n
        if contact.nodes is not None:
            nodes = node_indices(model.body(contact.body), contact.nodes)
            points = [material(contact.body, node=i, offset=offset) for i in nodes]
        else:
            rows = [None] if contact.points is None else list(np.asarray(contact.points, float))
            points = [material(contact.body, at=row, offset=offset) for row in rows]
        _contact_points(layout, part, first, len(layout.normals) - 1, points)
    elif isinstance(contact, SphereContact):
        centre_a, centre_b = material(contact.body_a, contact.at_a), material(contact.body_b, contact.at_b)
        radius_a = float(np.asarray(contact.radius_a))

        def direction(q):  # from a to b: the force on b
            d = centre_b(q) - centre_a(q)
            return d / jnp.maximum(jnp.linalg.norm(d), jnp.finfo(d.dtype).tiny)

        def touch(q):
            return centre_a(q) + radius_a * direction(q)

        layout.normals.append(direction)
        _contact_points(layout, part, first, len(layout.normals) - 1, [touch])
    elif isinstance(contact, FaceContact):
        n_b = np.asarray(contact.normal, float) / np.linalg.norm(contact.normal)
        origin = np.asarray(contact.origin, float)
        face, tip = material(contact.body_b, origin), material(contact.body_b, origin + n_b)

        def normal(q):  # the face's normal, turning with body b: the force on body a
            d = tip(q) - face(q)
            return d / jnp.linalg.norm(d)

        layout.normals.append(normal)
        points = [material(contact.body_a, at=row) for row in np.asarray(contact.points, float)]
        _contact_points(layout, part, first, len(layout.normals) - 1, points)


__all__ = ["embed_array", "gravity_of", "layout_of", "material_points", "orientation"]
