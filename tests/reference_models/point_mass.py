"""Point-mass models: the bouncing ball and the rigid pendulum against a wall."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from nsga_jax._custom_types import Matrix, Scalar, Vector
from nsga_jax._models import Model
from nsga_jax._util import as_float
from nsga_jax._validation import POSITIVE, UNIT_INTERVAL

from .rules import side_rule


class BouncingBall(Model):
    """A point mass above a horizontal floor, under gravity.

    Coordinate q = [z], the height of the point above the floor [m] (upward
    positive); one unilateral constraint g = z >= 0 with restitution e.
    """

    m: Scalar = eqx.field(converter=as_float)
    gravity: Scalar = eqx.field(converter=as_float)
    e: Scalar = eqx.field(converter=as_float)

    ranges = {"m": POSITIVE, "e": UNIT_INTERVAL}

    n_dof = 1
    n_unilateral = 1
    constant_mass = True
    linear_force = True
    velocity_dependent_force = False
    linear_constraints = True

    @property
    def mbar(self) -> Scalar:
        return self.m

    def mass(self, q: Vector) -> Matrix:
        return self.m * jnp.eye(1, dtype=q.dtype)

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        return self.m * x

    def force(self, q: Vector, v: Vector, t: Scalar) -> Vector:
        return -self.m * self.gravity * jnp.ones_like(q)

    def unilateral(self, q: Vector) -> jax.Array:
        return q[:1]

    @property
    def restitution(self) -> jax.Array:
        return self.e[None]

    def energy(self, q: Vector, v: Vector) -> Scalar:
        """Kinetic + potential energy [J]."""
        return 0.5 * self.m * v[0] ** 2 + self.m * self.gravity * q[0]


class RigidPendulum(Model):
    """A point mass on a massless rigid rod pivoting at the origin, and a wall.

    Coordinates q = [x, y] [m] (y upward). Bilateral (nonlinear) rod constraint
    g^B = (x² + y² - l²) / (2 l) = 0; unilateral wall constraint
    g^U = side (x - wall_x) >= 0, side = ±1 the side where the mass starts.
    """

    m: Scalar = eqx.field(converter=as_float)
    length: Scalar = eqx.field(converter=as_float)
    gravity: Scalar = eqx.field(converter=as_float)
    wall_x: Scalar = eqx.field(converter=as_float)
    side: Scalar = eqx.field(converter=as_float)
    e: Scalar = eqx.field(converter=as_float)

    ranges = {"m": POSITIVE, "length": POSITIVE, "e": UNIT_INTERVAL}

    def invalid(self) -> str | None:
        return side_rule(self.side)

    n_dof = 2
    n_bilateral = 1
    n_unilateral = 1
    constant_mass = True
    linear_force = True
    velocity_dependent_force = False

    @property
    def mbar(self) -> Scalar:
        return self.m

    def mass(self, q: Vector) -> Matrix:
        return self.m * jnp.eye(2, dtype=q.dtype)

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        return self.m * x

    def force(self, q: Vector, v: Vector, t: Scalar) -> Vector:
        return jnp.stack([jnp.zeros((), q.dtype), (-self.m * self.gravity).astype(q.dtype)])

    def bilateral(self, q: Vector) -> jax.Array:
        return ((q[0] ** 2 + q[1] ** 2 - self.length**2) / (2.0 * self.length))[None]

    def unilateral(self, q: Vector) -> jax.Array:
        return (self.side * (q[0] - self.wall_x))[None]

    @property
    def restitution(self) -> jax.Array:
        return self.e[None]

    def angular_speed(self, q: Vector, v: Vector) -> float:
        """|v| / l [rad/s]: the rod's angular speed."""
        return float(jnp.linalg.norm(v) / self.length)

    def energy(self, q: Vector, v: Vector) -> Scalar:
        """Kinetic + potential energy [J] (zero potential at the pivot height)."""
        return 0.5 * self.m * (v @ v) + self.m * self.gravity * q[1]
