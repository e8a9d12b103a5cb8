"""A contact between two bodies: material points of one against a face of the other.

The face is a plane fixed in body b (a line in 2D): it moves and turns with
b. The gap of point i of body a is its distance to that plane,
``g_i = n_b(q_b) · (x_i(q_a) - o_b(q_b))`` [m], with ``o_b`` the face's
origin and ``n_b`` its outward unit normal, both in b's frame and carried by
b's motion. Friction acts on the relative slip of point i and the material
point of b under it, on tangents that turn with the face.

A face may be bounded: a rectangle (a segment in 2D) of half-sides
``half_extent`` on its tangents, widened by ``margin``. A point that is not
over the face, or deeper than ``depth`` below it, is out of its reach: its
gap is then the positive constant ``sum(half_extent)``, so that it takes no
part in the contact (the gap jumps where a point crosses an edge: touching,
it leaves the face; under it, it meets the face). Stacked boxes use it: the
corners of the upper box's bottom on the lower box's top face, and the
reverse, so that a box tipping over an edge pivots on it.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Scalar, Vector
from .._util import as_float
from .._validation import UNIT_INTERVAL, Range
from .base import AbstractBody, AbstractContact, point
from .contacts import friction_rule, material_velocity, tangent_basis


def _optional_float(x):
    return None if x is None else as_float(x)


class FaceContact(AbstractContact):
    """Points of body ``body_a`` against a face of body ``body_b``.

    Attributes:
        body_a, body_b: the two bodies' names (rigid bodies; b may be ``"ground"``).
        points: body-frame coordinates of a's points, (k, dim) [m].
        normal: the face's outward normal in b's frame (dim,), normalised at evaluation.
        origin: a point of the face in b's frame (dim,) [m].
        e: restitution, scalar or (k,).
        half_extent: half-sides of the face (dim - 1,) [m] along its tangents
            (:func:`~nsga_jax._system.contacts.tangent_basis` of ``normal``, in
            b's frame); ``None`` (the default): an unbounded plane.
        margin: widening [m] of a bounded face on each side (negative: narrowing).
        depth: how deep below a bounded face [m] a point over it is still in
            contact (``None``: any depth).
        mu: Coulomb friction coefficient (>= 0), scalar or (k,); ``None``: frictionless.
    """

    body_a: str = eqx.field(static=True)
    body_b: str = eqx.field(static=True)
    points: Vector = eqx.field(converter=as_float)
    normal: Vector = eqx.field(converter=as_float)
    origin: Vector = eqx.field(converter=as_float)
    e: Vector = eqx.field(converter=as_float)
    half_extent: Vector | None = eqx.field(converter=_optional_float, default=None, kw_only=True)
    margin: Scalar = eqx.field(converter=as_float, default=0.0, kw_only=True)
    depth: Scalar | None = eqx.field(converter=_optional_float, default=None, kw_only=True)
    mu: Vector | None = eqx.field(converter=_optional_float, default=None, kw_only=True)

    ranges = {"e": UNIT_INTERVAL, "half_extent": Range(0.0, lo_open=True), "depth": Range(0.0, lo_open=True),
              "mu": Range(0.0)}

    def invalid(self) -> str | None:
        n = np.asarray(self.normal)
        if n.ndim != 1 or n.shape[0] not in (2, 3) or not np.linalg.norm(n) > 0:
            return f"normal must be a non-zero vector of 2 or 3 coordinates, got {n.tolist()}"
        if np.shape(self.origin) != n.shape:
            return f"origin must have the normal's {n.shape[0]} coordinates, got shape {np.shape(self.origin)}"
        if np.ndim(self.points) != 2 or np.shape(self.points)[1] != n.shape[0]:
            return f"points must have shape (k, {n.shape[0]}), got {np.shape(self.points)}"
        if self.half_extent is not None and np.shape(self.half_extent) != (n.shape[0] - 1,):
            return f"half_extent must have {n.shape[0] - 1} values (one per tangent), got {np.shape(self.half_extent)}"
        if self.half_extent is not None and not np.all(np.asarray(self.half_extent) + float(self.margin) > 0):
            return (f"margin narrows the face to nothing: half_extent + margin must be > 0, "
                    f"got margin {float(self.margin)}")
        if self.half_extent is None and self.depth is not None:
            return "depth bounds a face with half_extent; an unbounded plane has no depth"
        return None

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body_a, self.body_b)

    def count(self, bodies) -> int:
        return self.points.shape[-2]

    def _frame(self, body: AbstractBody, q: Vector) -> tuple[Vector, Vector, Vector]:
        """The face's world origin (dim,), unit normal (dim,) and unit tangents (dim - 1, dim)."""
        dtype = q.dtype
        n_b = (self.normal / jnp.linalg.norm(self.normal)).astype(dtype)
        o_b = self.origin.astype(dtype)
        o = point(body, q, o_b, None)
        n = point(body, q, o_b + n_b, None) - o
        t = jax.vmap(lambda t_b: point(body, q, o_b + t_b, None) - o)(tangent_basis(n_b))
        return o, n / jnp.linalg.norm(n), t / jnp.linalg.norm(t, axis=-1, keepdims=True)

    def _points(self, body: AbstractBody, q: Vector) -> Vector:
        return jax.vmap(lambda X: point(body, q, X, None))(self.points.astype(q.dtype))

    def evaluate(self, bodies, qs):
        o, n, t = self._frame(bodies[1], qs[1])
        d = self._points(bodies[0], qs[0]) - o  # (k, dim)
        gap = d @ n
        if self.half_extent is None:
            return gap
        half = self.half_extent.astype(gap.dtype)
        over = jnp.all(jnp.abs(d @ t.T) <= half + self.margin.astype(gap.dtype), axis=-1)
        if self.depth is not None:
            over = over & (gap >= -self.depth.astype(gap.dtype))
        return jnp.where(over, gap, jnp.sum(half))

    def slip_velocity(self, bodies, qs, vs):
        (body_a, body_b), (q_a, q_b), (v_a, v_b) = bodies, qs, vs
        o, _, t = self._frame(body_b, q_b)
        X_a = self.points.astype(q_a.dtype)
        x = self._points(body_a, q_a)
        rate_a = jax.vmap(lambda X: jax.jvp(lambda y: point(body_a, y, X, None), (q_a,), (v_a,))[1])(X_a)
        o_b = self.origin.astype(q_b.dtype)
        rate_b = jax.vmap(lambda p: material_velocity(body_b, q_b, v_b, o_b, None, p - o))(x)
        return (rate_a - rate_b) @ t.T

    def restitution(self, bodies) -> Vector:
        return jnp.broadcast_to(self.e, (self.count(bodies),))

    def is_linear(self, bodies) -> bool:
        return False

    def invalid_on(self, bodies) -> str | None:
        a, b = bodies
        if a.dim != b.dim:
            return f"bodies a and b live in {a.dim} and {b.dim} dimensions"
        if a.dim != self.normal.shape[-1]:
            return f"the bodies live in {a.dim} dimensions, the normal has {self.normal.shape[-1]}"
        if a.has_nodes or b.has_nodes:
            return "a face contact acts between rigid bodies (points in body-frame coordinates)"
        if jnp.ndim(self.e) == 1 and self.e.shape[0] != self.count(bodies):
            return f"e must be one value or one per point ({self.count(bodies)}), got {self.e.shape[0]}"
        return friction_rule(self, bodies)
