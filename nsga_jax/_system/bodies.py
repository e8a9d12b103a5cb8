"""Rigid bodies of a system: point masses and planar rigid bodies."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._custom_types import Matrix, Scalar, Vector
from .._util import as_float
from .._validation import POSITIVE
from .base import AbstractBody


def _vector_rule(name: str, value, dims: tuple[int, ...]) -> str | None:
    shape = np.shape(value)
    if len(shape) != 1 or shape[0] not in dims:
        allowed = " or ".join(str(d) for d in dims)
        return f"{name} must be a vector of {allowed} coordinates [m], got shape {shape}"
    return None


class PointMass(AbstractBody):
    """A point mass in 1, 2 or 3 dimensions (the length of ``position``).

    Coordinates q = its position x (dim,) [m]. Its only material point is
    itself (``at`` must be zero).

    Attributes:
        mass: m [kg].
        position: initial position (dim,) [m].
        velocity: initial velocity (dim,) [m/s].
    """

    mass_: Scalar = eqx.field(converter=as_float)
    position0: Vector = eqx.field(converter=as_float)
    velocity0: Vector = eqx.field(converter=as_float)

    ranges = {"mass_": POSITIVE}

    def __init__(self, mass, position, velocity=None):
        self.mass_ = as_float(mass)
        self.position0 = as_float(position)
        self.velocity0 = jnp.zeros_like(self.position0) if velocity is None else as_float(velocity)

    def invalid(self) -> str | None:
        return _vector_rule("position", self.position0, (1, 2, 3)) or \
            _vector_rule("velocity", self.velocity0, (np.size(self.position0),))

    @property
    def dim(self) -> int:
        return self.position0.shape[-1]

    @property
    def n_dof(self) -> int:
        return self.dim

    @property
    def bandwidth(self) -> int:
        return 0

    @property
    def total_mass(self) -> Scalar:
        return self.mass_

    def initial_state(self) -> tuple[Vector, Vector]:
        return self.position0, self.velocity0

    def mass(self, q: Vector) -> Matrix:
        return self.mass_ * jnp.eye(self.dim, dtype=q.dtype)

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        return self.mass_ * x

    def gravity_force(self, g: Vector) -> Vector:
        return self.mass_ * g

    def position(self, q: Vector, at: Vector, node: int | None) -> Vector:
        return q

    def invalid_anchor(self, at, node) -> str | None:
        rule = super().invalid_anchor(at, node)
        if rule is None and np.any(np.asarray(at) != 0):
            return f"a point mass has one material point, at = 0; got at = {np.asarray(at).tolist()}"
        return rule


def rotation_2d(angle: Scalar) -> Matrix:
    """R(θ) = [[cos θ, -sin θ], [sin θ, cos θ]], shape (2, 2)."""
    c, s = jnp.cos(angle), jnp.sin(angle)
    return jnp.stack([jnp.stack([c, -s]), jnp.stack([s, c])])


class RigidBody2D(AbstractBody):
    """A planar rigid body.

    Coordinates q = [x, y, θ]: the centre of mass [m] and the rotation [rad]
    from the body frame to the world. A material point with body coordinates
    X (2,) is at ``r + R(θ) X`` (nonlinear in θ); M = diag(m, m, J) is constant.

    Attributes:
        mass: m [kg]; inertia: J about the centre of mass [kg m²].
        position: initial centre of mass (2,) [m]; angle: initial θ [rad].
        velocity: initial velocity of the centre of mass (2,) [m/s];
        angular_velocity: initial θ̇ [rad/s].
    """

    mass_: Scalar = eqx.field(converter=as_float)
    inertia: Scalar = eqx.field(converter=as_float)
    position0: Vector = eqx.field(converter=as_float)
    angle0: Scalar = eqx.field(converter=as_float)
    velocity0: Vector = eqx.field(converter=as_float)
    angular_velocity0: Scalar = eqx.field(converter=as_float)

    ranges = {"mass_": POSITIVE, "inertia": POSITIVE}
    linear_points = False

    def __init__(self, mass, inertia, position, angle=0.0, velocity=(0.0, 0.0), angular_velocity=0.0):
        self.mass_, self.inertia = as_float(mass), as_float(inertia)
        self.position0, self.angle0 = as_float(position), as_float(angle)
        self.velocity0, self.angular_velocity0 = as_float(velocity), as_float(angular_velocity)

    def invalid(self) -> str | None:
        return _vector_rule("position", self.position0, (2,)) or _vector_rule("velocity", self.velocity0, (2,))

    dim = 2  # type: ignore[assignment]
    n_dof = 3  # type: ignore[assignment]

    @property
    def bandwidth(self) -> int:
        return 0

    @property
    def total_mass(self) -> Scalar:
        return self.mass_

    def initial_state(self) -> tuple[Vector, Vector]:
        q0 = jnp.concatenate([self.position0, self.angle0[None]])
        v0 = jnp.concatenate([self.velocity0, self.angular_velocity0[None]])
        return q0, v0

    def mass(self, q: Vector) -> Matrix:
        return jnp.diag(jnp.stack([self.mass_, self.mass_, self.inertia]).astype(q.dtype))

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        return jnp.stack([self.mass_, self.mass_, self.inertia]).astype(x.dtype) * x

    def gravity_force(self, g: Vector) -> Vector:
        return jnp.concatenate([self.mass_ * g, jnp.zeros((1,), g.dtype)])

    def position(self, q: Vector, at: Vector, node: int | None) -> Vector:
        c, s = jnp.cos(q[2]), jnp.sin(q[2])
        X = at.astype(q.dtype)
        return q[:2] + jnp.stack([c * X[0] - s * X[1], s * X[0] + c * X[1]])

    def angle(self, q: Vector, node: int | None) -> Scalar:
        return q[2]

    def angular_speed(self, q: Vector, v: Vector) -> Scalar:
        return jnp.abs(v[2])

