"""Joints: bilateral constraints between two bodies (or a body and the ground).

Every joint names two anchors (see :mod:`nsga_jax._system.base`): body ``a``
with ``at_a`` or ``node_a``, body ``b`` with ``at_b`` or ``node_b``. Its
constraints are lengths [m] (angles are multiplied by a length, ``scale``, so
that every row of g_q is of the same scale, as the rigidity constraints of
natural coordinates are).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Scalar, Vector
from .._util import as_float
from .._validation import POSITIVE
from .base import AbstractBody, AbstractJoint, anchor, point


class AbstractTwoPointJoint(AbstractJoint):
    """A joint between anchor a (``body_a``, ``at_a``/``node_a``) and anchor b."""

    body_a: str = eqx.field(static=True)
    body_b: str = eqx.field(static=True)
    at_a: Vector = eqx.field(converter=anchor, default=None, kw_only=True)
    at_b: Vector = eqx.field(converter=anchor, default=None, kw_only=True)
    node_a: int | None = eqx.field(static=True, default=None, kw_only=True)
    node_b: int | None = eqx.field(static=True, default=None, kw_only=True)

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body_a, self.body_b)

    def points(self, bodies: tuple[AbstractBody, ...], qs: tuple[Vector, ...]) -> tuple[Vector, Vector]:
        """World positions of the two anchors, each (dim,) [m]."""
        return (point(bodies[0], qs[0], self.at_a, self.node_a), point(bodies[1], qs[1], self.at_b, self.node_b))

    def invalid_on(self, bodies: tuple[AbstractBody, ...]) -> str | None:
        if bodies[0].dim != bodies[1].dim:
            return f"bodies a and b live in {bodies[0].dim} and {bodies[1].dim} dimensions"
        return (_anchor_rule("a", bodies[0], self.at_a, self.node_a)
                or _anchor_rule("b", bodies[1], self.at_b, self.node_b))


def _anchor_rule(side: str, body: AbstractBody, at, node) -> str | None:
    rule = body.invalid_anchor(at, node)
    return f"anchor {side} on {type(body).__name__}: {rule}" if rule else None


class Pin(AbstractTwoPointJoint):
    """Two material points held together: a planar revolute joint (dim 2), a
    spherical joint (dim 3), or a node pinned to a body or to the ground.
    ``dim`` constraints ``x_a - x_b = 0`` [m]."""

    def count(self, bodies) -> int:
        return bodies[0].dim

    def evaluate(self, bodies, qs):
        xa, xb = self.points(bodies, qs)
        return xa - xb

    def is_linear(self, bodies) -> bool:
        return all(b.linear_points for b in bodies)


class Distance(AbstractTwoPointJoint):
    """A massless rigid rod of ``length`` L [m] between the two points:
    ``(|x_a - x_b|² - L²) / (2 L) = 0`` [m] (one constraint)."""

    length: Scalar = eqx.field(converter=as_float, kw_only=True)
    ranges = {"length": POSITIVE}

    def count(self, bodies) -> int:
        return 1

    def evaluate(self, bodies, qs):
        xa, xb = self.points(bodies, qs)
        d = xa - xb
        return ((d @ d - self.length**2) / (2.0 * self.length))[None]

    def is_linear(self, bodies) -> bool:
        return False

    def angular_speed(self, bodies, qs, vs):
        """The rod's angular speed ``|v_a - v_b| / L`` [rad/s] (its length held)."""
        _, (va, vb) = jax.jvp(lambda qa, qb: self.points(bodies, (qa, qb)), qs, vs)
        return jnp.linalg.norm(va - vb) / self.length


class Weld(AbstractTwoPointJoint):
    """Planar weld (or clamp of a beam node): the points coincide and the
    relative angle ``θ_b - θ_a`` keeps its value ``angle`` [rad]; three
    constraints, the angle one multiplied by ``scale`` [m]."""

    angle: Scalar = eqx.field(converter=as_float, default=0.0, kw_only=True)
    scale: Scalar = eqx.field(converter=as_float, default=1.0, kw_only=True)
    ranges = {"scale": POSITIVE}

    def count(self, bodies) -> int:
        return 3

    def evaluate(self, bodies, qs):
        xa, xb = self.points(bodies, qs)
        turn = bodies[1].angle(qs[1], self.node_b) - bodies[0].angle(qs[0], self.node_a) - self.angle
        return jnp.concatenate([xa - xb, (self.scale * turn)[None]])

    def is_linear(self, bodies) -> bool:
        return all(b.linear_points and b.linear_angle for b in bodies)

    def invalid_on(self, bodies) -> str | None:
        if any(b.dim != 2 for b in bodies):
            return "a weld joins planar bodies (dim 2)"
        for side, b in zip("ab", bodies):
            if not b.has_angle:
                return f"body {side} ({type(b).__name__}) has no orientation to weld"
        return super().invalid_on(bodies)


class Slider(AbstractTwoPointJoint):
    """Planar prismatic joint: point b moves along the line through point a
    with direction ``axis`` (in body a's frame, unit length after
    normalisation); where both bodies have an orientation their relative
    angle also stays ``angle`` [rad] (times ``scale`` [m]). One or two constraints."""

    axis: Vector = eqx.field(converter=as_float, kw_only=True)
    angle: Scalar = eqx.field(converter=as_float, default=0.0, kw_only=True)
    scale: Scalar = eqx.field(converter=as_float, default=1.0, kw_only=True)
    fixed_angle: bool = eqx.field(static=True, default=True, kw_only=True)
    ranges = {"scale": POSITIVE}

    def invalid(self) -> str | None:
        a = np.asarray(self.axis)
        if a.shape != (2,) or not np.linalg.norm(a) > 0:
            return f"axis must be a non-zero vector of 2 coordinates, got {a.tolist()}"
        return None

    def count(self, bodies) -> int:
        return 2 if self.fixed_angle else 1

    def evaluate(self, bodies, qs):
        xa, xb = self.points(bodies, qs)
        axis = self.axis / jnp.linalg.norm(self.axis)
        if bodies[0].has_angle:
            c, s = jnp.cos(bodies[0].angle(qs[0], self.node_a)), jnp.sin(bodies[0].angle(qs[0], self.node_a))
            axis = jnp.stack([c * axis[0] - s * axis[1], s * axis[0] + c * axis[1]])
        normal = jnp.stack([-axis[1], axis[0]])
        rows = [(normal @ (xb - xa))[None]]
        if self.fixed_angle:
            turn = bodies[1].angle(qs[1], self.node_b) - bodies[0].angle(qs[0], self.node_a) - self.angle
            rows.append((self.scale * turn)[None])
        return jnp.concatenate(rows)

    def is_linear(self, bodies) -> bool:
        return all(b.linear_points for b in bodies) and not (bodies[0].has_angle and bodies[0].n_dof > 0)

    def invalid_on(self, bodies) -> str | None:
        if any(b.dim != 2 for b in bodies):
            return "a slider joins planar bodies (dim 2)"
        if self.fixed_angle:
            for side, b in zip("ab", bodies):
                if not b.has_angle:
                    return (f"body {side} ({type(b).__name__}) has no orientation: give fixed_angle = false "
                            "(a point on a line)")
        return super().invalid_on(bodies)
