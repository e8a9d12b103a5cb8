"""Applied forces: gravity, spring–dampers, torsional springs and prescribed loads."""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._custom_types import Scalar, Vector
from .._util import as_float
from .._validation import Range
from .base import AbstractBody, AbstractForce, anchor, point, point_force


class Gravity(AbstractForce):
    """A uniform acceleration ``acceleration`` (dim,) [m/s²] on the mass of
    every body named in ``bodies`` (the builder fills in all of them)."""

    acceleration: Vector = eqx.field(converter=as_float)
    on: tuple[str, ...] = eqx.field(static=True, default=(), kw_only=True)

    @property
    def bodies(self) -> tuple[str, ...]:
        return self.on

    def depends_on_state(self, bodies) -> bool:
        return False

    def generalized(self, bodies, qs, vs, t):
        return tuple(b.gravity_force(self.acceleration.astype(q.dtype)) for b, q in zip(bodies, qs))

    def on_body(self, body: AbstractBody, dtype) -> Vector:
        """The generalised force (k,) [N] on one body."""
        return body.gravity_force(self.acceleration.astype(dtype))

    def potential(self, bodies, qs):
        return -sum((b.gravity_force(self.acceleration.astype(q.dtype)) @ q for b, q in zip(bodies, qs)),
                    jnp.zeros(()))

    def is_linear(self, bodies) -> bool:
        return True

    def invalid_on(self, bodies) -> str | None:
        for b in bodies:
            if b.dim != self.acceleration.shape[-1]:
                return (f"acceleration has {self.acceleration.shape[-1]} coordinates; the bodies live in "
                        f"{b.dim} dimensions")
        return None


class SpringDamper(AbstractForce):
    """A linear spring–damper between two anchors: tension
    ``k (l - rest_length) + c dl/dt`` along the line between them (l their
    distance [m]); ``stiffness`` k [N/m], ``damping`` c [N s/m]."""

    body_a: str = eqx.field(static=True)
    body_b: str = eqx.field(static=True)
    stiffness: Scalar = eqx.field(converter=as_float)
    rest_length: Scalar = eqx.field(converter=as_float)
    damping: Scalar = eqx.field(converter=as_float, default=0.0, kw_only=True)
    at_a: Vector = eqx.field(converter=anchor, default=None, kw_only=True)
    at_b: Vector = eqx.field(converter=anchor, default=None, kw_only=True)
    node_a: int | None = eqx.field(static=True, default=None, kw_only=True)
    node_b: int | None = eqx.field(static=True, default=None, kw_only=True)

    ranges = {"stiffness": Range(0.0), "rest_length": Range(0.0), "damping": Range(0.0)}
    velocity_dependent = True

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body_a, self.body_b)

    def _points(self, bodies, qs):
        return point(bodies[0], qs[0], self.at_a, self.node_a), point(bodies[1], qs[1], self.at_b, self.node_b)

    def generalized(self, bodies, qs, vs, t):
        import jax

        xa, xb = self._points(bodies, qs)
        (_, _), (va, vb) = jax.jvp(lambda qa, qb: self._points(bodies, (qa, qb)), qs, vs)
        d = xb - xa
        length = jnp.sqrt(d @ d)
        direction = d / length
        tension = self.stiffness * (length - self.rest_length) + self.damping * (direction @ (vb - va))
        return (point_force(bodies[0], qs[0], self.at_a, self.node_a, tension * direction),
                point_force(bodies[1], qs[1], self.at_b, self.node_b, -tension * direction))

    def potential(self, bodies, qs):
        xa, xb = self._points(bodies, qs)
        return 0.5 * self.stiffness * (jnp.linalg.norm(xb - xa) - self.rest_length) ** 2

    def is_linear(self, bodies) -> bool:
        return False

    def invalid_on(self, bodies) -> str | None:
        if bodies[0].dim != bodies[1].dim:
            return f"bodies a and b live in {bodies[0].dim} and {bodies[1].dim} dimensions"
        for side, b, at, node in (("a", bodies[0], self.at_a, self.node_a), ("b", bodies[1], self.at_b, self.node_b)):
            rule = b.invalid_anchor(at, node)
            if rule:
                return f"anchor {side}: {rule}"
        return None


class TorsionalSpring(AbstractForce):
    """A torsional spring–damper between the orientations of two planar bodies
    (or a body and the ground): moment ``-k (θ_b - θ_a - rest_angle) - c (θ̇_b - θ̇_a)``
    on b and its opposite on a; ``stiffness`` k [N m/rad], ``damping`` c [N m s/rad]."""

    body_a: str = eqx.field(static=True)
    body_b: str = eqx.field(static=True)
    stiffness: Scalar = eqx.field(converter=as_float)
    rest_angle: Scalar = eqx.field(converter=as_float, default=0.0, kw_only=True)
    damping: Scalar = eqx.field(converter=as_float, default=0.0, kw_only=True)
    node_a: int | None = eqx.field(static=True, default=None, kw_only=True)
    node_b: int | None = eqx.field(static=True, default=None, kw_only=True)

    ranges = {"stiffness": Range(0.0), "damping": Range(0.0)}
    velocity_dependent = True

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body_a, self.body_b)

    def _turn(self, bodies, qs):
        return bodies[1].angle(qs[1], self.node_b) - bodies[0].angle(qs[0], self.node_a)

    def generalized(self, bodies, qs, vs, t):
        import jax

        def energy(qa, qb):
            return 0.5 * self.stiffness * (self._turn(bodies, (qa, qb)) - self.rest_angle) ** 2

        _, rate = jax.jvp(lambda qa, qb: self._turn(bodies, (qa, qb)), qs, vs)
        dissipation = jax.grad(lambda qa, qb: self._turn(bodies, (qa, qb)), argnums=(0, 1))(*qs)
        elastic = jax.grad(energy, argnums=(0, 1))(*qs)
        return tuple(-de - self.damping * rate * dt for de, dt in zip(elastic, dissipation))

    def potential(self, bodies, qs):
        return 0.5 * self.stiffness * (self._turn(bodies, qs) - self.rest_angle) ** 2

    def is_linear(self, bodies) -> bool:
        return all(b.linear_angle for b in bodies)

    def invalid_on(self, bodies) -> str | None:
        for side, b in zip("ab", bodies):
            if not b.has_angle:
                return f"body {side} ({type(b).__name__}) has no planar orientation"
        return None


class PrescribedForce(AbstractForce):
    """A force given as a function of time at an anchor of one body:
    ``F(t) = amplitude (constant + sin(2π frequency t + phase))`` along ``direction``
    (dim,) [N], or ``function(t) -> (dim,)`` [N] where given (Python only).
    With ``torque = true`` the load is a moment [N m] on a planar body's angle instead."""

    body: str = eqx.field(static=True)
    direction: Vector = eqx.field(converter=as_float)
    amplitude: Scalar = eqx.field(converter=as_float, default=1.0, kw_only=True)
    constant: Scalar = eqx.field(converter=as_float, default=1.0, kw_only=True)
    frequency: Scalar = eqx.field(converter=as_float, default=0.0, kw_only=True)
    phase: Scalar = eqx.field(converter=as_float, default=0.0, kw_only=True)
    at: Vector = eqx.field(converter=anchor, default=None, kw_only=True)
    node: int | None = eqx.field(static=True, default=None, kw_only=True)
    torque: bool = eqx.field(static=True, default=False, kw_only=True)
    function: Callable | None = eqx.field(static=True, default=None, kw_only=True)

    ranges = {"frequency": Range(0.0)}
    conservative = False

    def depends_on_state(self, bodies) -> bool:
        return not self.is_linear(bodies)

    @property
    def bodies(self) -> tuple[str, ...]:
        return (self.body,)

    def load(self, t: Scalar) -> Vector:
        """The force (dim,) [N] (or the moment (1,) [N m]) at time t [s]."""
        if self.function is not None:
            return jnp.asarray(self.function(t), dtype=jnp.result_type(t, float))
        return self.amplitude * (self.constant + jnp.sin(2 * np.pi * self.frequency * t + self.phase)) * self.direction

    def generalized(self, bodies, qs, vs, t):
        body, q = bodies[0], qs[0]
        F = self.load(t).astype(q.dtype)
        if self.torque:
            import jax

            return (jax.grad(lambda x: body.angle(x, self.node))(q) * F[0],)
        return (point_force(body, q, self.at, self.node, F),)

    def is_linear(self, bodies) -> bool:
        return bodies[0].linear_angle if self.torque else bodies[0].linear_points

    def invalid_on(self, bodies) -> str | None:
        body = bodies[0]
        if self.torque:
            if not body.has_angle:
                return f"a torque needs a body with a planar orientation, not {type(body).__name__}"
            return None
        if self.function is None and self.direction.shape[-1] != body.dim:
            return f"direction has {self.direction.shape[-1]} coordinates; the body lives in {body.dim} dimensions"
        return body.invalid_anchor(self.at, self.node)

