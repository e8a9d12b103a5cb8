"""Contacts: unilateral constraints g(q) >= 0 with Newton restitution and,
where a coefficient ``mu`` is given, Coulomb friction.

Each contact kind gives its gaps [m] (positive apart, zero touching) from
the anchors it names (see :mod:`nsga_jax._system.base`) and, with friction,
the slip velocity of its contact points on the contact's tangents: one
tangent in a planar system, two in space (isotropic friction: any
orthonormal pair serves).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Scalar, Vector
from .._results import ConfigError
from .._util import as_float
from .._validation import UNIT_INTERVAL, Range
from .base import AbstractBody, AbstractContact, point


def _nodes(x) -> tuple[int, ...] | str | None:
    """Node indices as a tuple of ints; a name (a node set of the body) as it is."""
    return x if x is None or isinstance(x, str) else tuple(int(i) for i in np.ravel(x))


def node_indices(body: AbstractBody, nodes: tuple[int, ...] | str) -> tuple[int, ...]:
    """Node indices named by ``nodes``: indices as they are, a name resolved
    by the body's ``node_set`` (a solid's faces: ``"bottom"``, ...)."""
    return body.node_set(nodes) if isinstance(nodes, str) else nodes  # type: ignore[attr-defined]


def node_points(body: AbstractBody, q: Vector, nodes: tuple[int, ...]) -> Vector:
    """World positions (k, dim) [m] of the body's ``nodes``: in one gather where
    the body has ``node_positions`` (a solid's face of many nodes), else node by node."""
    gather = getattr(body, "node_positions", None)
    if gather is not None:
        return gather(q, nodes)
    return jnp.stack([point(body, q, jnp.zeros((0,), q.dtype), i) for i in nodes])


def _optional_float(x):
    return None if x is None else as_float(x)


def tangent_basis(normal: Vector) -> Vector:
    """Unit tangents orthogonal to the unit ``normal`` (dim,), shape (dim - 1, dim):
    in 2D the normal turned by +90°, in 3D a right-handed pair (t1, t2, n)."""
    if normal.shape[-1] == 2:
        return jnp.stack([-normal[1], normal[0]])[None]
    axis = jnp.eye(3, dtype=normal.dtype)[jnp.argmin(jnp.abs(normal))]  # the axis least aligned with n
    t1 = jnp.cross(axis, normal)
    t1 = t1 / jnp.linalg.norm(t1)
    return jnp.stack([t1, jnp.cross(normal, t1)])


def material_velocity(body: AbstractBody, q: Vector, v: Vector, at: Vector, node: int | None,
                      offset: Vector | None = None) -> Vector:
    """Velocity (dim,) [m/s] of the material point at world ``offset`` (dim,) [m]
    from an anchor (``None``: the anchor itself): on a body that turns, the
    point at body-frame coordinates ``at + (dx/dX)^{-1} offset``; nodes and
    point masses do not turn, and their points share the anchor's velocity."""
    turns = not body.has_nodes and offset is not None and body.n_dof > body.dim
    if turns:
        at = at if at.shape[-1] else jnp.zeros((body.dim,), q.dtype)
        frame = jax.jacfwd(lambda X: body.position(q, X, node))(at.astype(q.dtype))  # dx/dX (dim, dim)
        at = at + jnp.linalg.solve(frame, offset)
    return jax.jvp(lambda x: point(body, x, at, node), (q,), (v,))[1]


def friction_rule(contact, bodies) -> str | None:
    """Why a contact's ``mu`` cannot apply to these bodies, or ``None``."""
    mu = getattr(contact, "mu", None)
    if mu is None:
        return None
    if bodies[0].dim == 1:
        return "mu: friction needs a tangent direction (a 2D or 3D system); a 1D contact is frictionless"
    if jnp.ndim(mu) == 1 and mu.shape[0] != contact.count(bodies):
        return f"mu must be one value or one per point ({contact.count(bodies)}), got {mu.shape[0]}"
    if jnp.ndim(mu) > 1:
        return f"mu must be one value or one per point, got shape {jnp.shape(mu)}"
    return None


class PlaneContact(AbstractContact):
    """Material points of one body against a fixed plane (a line in 2D, a
    point in 1D) through ``origin`` with unit ``normal`` pointing to the
    admissible side: ``g_i = n · (x_i - origin) - radius >= 0``. With a
    radius, each point is the centre of a sphere (circle) of that radius.

    The points are ``points`` (body-frame coordinates, (k, dim), on a rigid
    body; ``None``: its origin) or ``nodes`` (indices, on a flexible body, or
    the name of one of its node sets: a solid's face, ``nodes="bottom"``).

    Attributes:
        normal: (dim,), normalised at evaluation. origin: (dim,) [m].
        e: restitution, scalar or (k,). radius [m].
        mu: Coulomb friction coefficient (>= 0), scalar or (k,); ``None``
            (the default): frictionless. With a radius, friction acts at the
            sphere's lowest point, so a spinning ball feels it.
    """

    body: str = eqx.field(static=True)
    normal: Vector = eqx.field(converter=as_float)
    origin: Vector = eqx.field(converter=as_float)
    e: Vector = eqx.field(converter=as_float)
    points: Vector | None = eqx.field(converter=lambda x: None if x is None else as_float(x), default=None,
                                      kw_only=True)
    nodes: tuple[int, ...] | str | None = eqx.field(static=True, default=None, kw_only=True, converter=_nodes)
    radius: Scalar = eqx.field(converter=as_float, default=0.0, kw_only=True)
    mu: Vector | None = eqx.field(converter=_optional_float, default=None, kw_only=True)

    ranges = {"e": UNIT_INTERVAL, "radius": Range(0.0), "mu": Range(0.0)}

    def invalid(self) -> str | None:
        n = np.asarray(self.normal)
        if n.ndim != 1 or n.shape[0] not in (1, 2, 3) or not np.linalg.norm(n) > 0:
            return f"normal must be a non-zero vector of 1, 2 or 3 coordinates, got {n.tolist()}"
        if np.shape(self.origin) != n.shape:
            return f"origin must have the normal's {n.shape[0]} coordinates, got shape {np.shape(self.origin)}"
        if self.points is not None and self.nodes is not None:
            return "points: give points (rigid body) or nodes (flexible body), not both"
        if self.points is not None and (np.ndim(self.points) != 2 or np.shape(self.points)[1] != n.shape[0]):
            return f"points must have shape (k, {n.shape[0]}), got {np.shape(self.points)}"
        return None

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body,)

    def count(self, bodies) -> int:
        if self.nodes is not None:
            return len(node_indices(bodies[0], self.nodes))
        return 1 if self.points is None else self.points.shape[-2]

    def _anchors(self, bodies, dtype) -> tuple[Vector, tuple[int | None, ...]]:
        """The points' body-frame coordinates (k, dim) (empty rows on nodes) and node indices."""
        if self.nodes is not None:
            nodes = node_indices(bodies[0], self.nodes)
            return jnp.zeros((len(nodes), 0), dtype), tuple(nodes)
        at = jnp.zeros((1, 0), dtype) if self.points is None else self.points.astype(dtype)
        return at, (None,) * at.shape[0]

    def slip_velocity(self, bodies, qs, vs):
        body, q, v = bodies[0], qs[0], vs[0]
        n = (self.normal / jnp.linalg.norm(self.normal)).astype(q.dtype)
        at, nodes = self._anchors(bodies, q.dtype)
        offset = -self.radius.astype(q.dtype) * n
        if self.nodes is None:
            rate = jax.vmap(lambda X: material_velocity(body, q, v, X, None, offset))(at)
        else:
            rate = jnp.stack([material_velocity(body, q, v, at[i], node) for i, node in enumerate(nodes)])
        return rate @ tangent_basis(n).T

    def evaluate(self, bodies, qs):
        body, q = bodies[0], qs[0]
        n = self.normal / jnp.linalg.norm(self.normal)
        if self.nodes is not None:
            x = node_points(body, q, node_indices(body, self.nodes))
        elif self.points is None:
            x = point(body, q, jnp.zeros((0,), q.dtype), None)[None]
        else:
            x = jax.vmap(lambda X: point(body, q, X, None))(self.points)
        return (x - self.origin.astype(q.dtype)) @ n.astype(q.dtype) - self.radius

    def restitution(self, bodies) -> Vector:
        return jnp.broadcast_to(self.e, (self.count(bodies),))

    def is_linear(self, bodies) -> bool:
        return bodies[0].linear_points

    def invalid_on(self, bodies) -> str | None:
        body = bodies[0]
        if body.dim != self.normal.shape[-1]:
            return f"the body lives in {body.dim} dimensions, the normal has {self.normal.shape[-1]}"
        if jnp.ndim(self.e) == 1 and self.e.shape[0] != self.count(bodies):
            return f"e must be one value or one per point ({self.count(bodies)}), got {self.e.shape[0]}"
        rule = friction_rule(self, bodies)
        if rule:
            return rule
        if body.has_nodes and self.nodes is None:
            return "a flexible body's points are named by nodes = [...]"
        if not body.has_nodes and self.nodes is not None:
            return "a rigid body's points are named by points = [[...], ...] (body-frame coordinates)"
        if isinstance(self.nodes, str):
            if not hasattr(body, "node_set"):
                return f"{type(body).__name__} has no named node sets: give nodes = [indices]"
            try:
                body.node_set(self.nodes)
            except ConfigError as error:
                return str(error)
            return None
        for i in self.nodes or ():
            rule = body.invalid_anchor(jnp.zeros((0,)), i)
            if rule:
                return rule
        return None


class SphereContact(AbstractContact):
    """Two spheres (circles in 2D, segments in 1D) of radii ``radius_a`` and
    ``radius_b`` centred at anchors of two bodies: ``g = |x_a - x_b| - r_a - r_b >= 0``.
    In 1D the distance is ``side (x_b - x_a)`` with ``side`` = ±1 the order of the two bodies
    on the line (the ball b on the positive side of a: +1).

    ``mu`` (>= 0, ``None``: frictionless) adds Coulomb friction on the
    relative slip of the two surfaces at the contact point (2D and 3D)."""

    body_a: str = eqx.field(static=True)
    body_b: str = eqx.field(static=True)
    radius_a: Scalar = eqx.field(converter=as_float)
    radius_b: Scalar = eqx.field(converter=as_float)
    e: Scalar = eqx.field(converter=as_float)
    at_a: Vector = eqx.field(converter=lambda x: jnp.zeros((0,)) if x is None else as_float(x), default=None,
                             kw_only=True)
    at_b: Vector = eqx.field(converter=lambda x: jnp.zeros((0,)) if x is None else as_float(x), default=None,
                             kw_only=True)
    side: float = eqx.field(static=True, default=1.0, kw_only=True)
    mu: Scalar | None = eqx.field(converter=_optional_float, default=None, kw_only=True)

    ranges = {"radius_a": Range(0.0), "radius_b": Range(0.0), "e": UNIT_INTERVAL, "mu": Range(0.0)}

    def invalid(self) -> str | None:
        if self.side not in (1.0, -1.0):
            return f"side must be +1 or -1, got {self.side}"
        return None

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body_a, self.body_b)

    def count(self, bodies) -> int:
        return 1

    def evaluate(self, bodies, qs):
        xa = point(bodies[0], qs[0], self.at_a, None)
        xb = point(bodies[1], qs[1], self.at_b, None)
        if bodies[0].dim == 1:
            distance = self.side * (xb[0] - xa[0])
        else:
            distance = jnp.linalg.norm(xa - xb)
        return (distance - self.radius_a - self.radius_b)[None]

    def restitution(self, bodies) -> Vector:
        return jnp.broadcast_to(self.e, (1,))

    def slip_velocity(self, bodies, qs, vs):
        xa = point(bodies[0], qs[0], self.at_a, None)
        xb = point(bodies[1], qs[1], self.at_b, None)
        d = xb - xa
        n = d / jnp.linalg.norm(d)  # from a to b
        va = material_velocity(bodies[0], qs[0], vs[0], self.at_a, None, self.radius_a.astype(d.dtype) * n)
        vb = material_velocity(bodies[1], qs[1], vs[1], self.at_b, None, -self.radius_b.astype(d.dtype) * n)
        return ((vb - va) @ tangent_basis(n).T)[None]

    def is_linear(self, bodies) -> bool:
        return bodies[0].dim == 1 and all(b.linear_points for b in bodies)

    def invalid_on(self, bodies) -> str | None:
        if bodies[0].dim != bodies[1].dim:
            return f"bodies a and b live in {bodies[0].dim} and {bodies[1].dim} dimensions"
        rule = friction_rule(self, bodies)
        if rule:
            return rule
        for side, b, at in (("a", bodies[0], self.at_a), ("b", bodies[1], self.at_b)):
            rule = b.invalid_anchor(at, None)
            if rule:
                return f"anchor {side}: {rule}"
        return None
