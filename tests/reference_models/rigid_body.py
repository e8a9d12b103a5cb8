"""A rigid body in natural coordinates with point–plane contacts (frictionless)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from nsga_jax._custom_types import Matrix, Scalar, Vector
from nsga_jax._elements.rigid_body import (
    angular_velocity,
    frame,
    natural_mass_matrix,
    point_heights,
    rigidity_constraints,
    second_moments,
)
from nsga_jax._models import Model
from nsga_jax._util import as_float
from nsga_jax._validation import POSITIVE, UNIT_INTERVAL


class RigidBody(Model):
    """One rigid body in natural coordinates q = [r, u, v, w] (12,) under gravity,
    with its contact points against the plane z = floor_z (optional).

    Attributes:
        mass_: mass m [kg]; inertia: inertia tensor at the centre of mass (3, 3) [kg m²].
        points: body coordinates of the contact points (k, 3) [m].
        gravity: gravitational acceleration (downward, along -z) [m/s²].
        floor_z: height of the floor [m].
        e: restitution coefficient of each contact point (k,).
        size: characteristic length scaling the rigidity constraints [m].
        contact: whether the floor exists (static; without it there are no
            unilateral constraints at all).
    """

    mass_: Scalar = eqx.field(converter=as_float)
    inertia: jax.Array = eqx.field(converter=as_float)
    points: jax.Array = eqx.field(converter=as_float)
    gravity: Scalar = eqx.field(converter=as_float)
    floor_z: Scalar = eqx.field(converter=as_float)
    e: jax.Array = eqx.field(converter=as_float)
    size: Scalar = eqx.field(converter=as_float)

    ranges = {"mass_": POSITIVE, "e": UNIT_INTERVAL, "size": POSITIVE}

    def invalid(self) -> str | None:
        J = np.asarray(self.inertia)
        if J.shape != (3, 3) or not np.allclose(J, J.T, rtol=1e-12, atol=0.0):
            return f"inertia must be a symmetric (3, 3) tensor [kg m^2], got {J.tolist()}"
        if np.linalg.eigvalsh(J).min() <= 0:
            return f"inertia must be positive definite, got eigenvalues {np.linalg.eigvalsh(J).tolist()}"
        return None
    contact: bool = eqx.field(static=True, default=True)

    n_dof = 12
    n_bilateral = 6
    constant_mass = True
    linear_force = True
    velocity_dependent_force = False

    @property
    def n_unilateral(self) -> int:
        return self.points.shape[-2] if self.contact else 0

    @property
    def mbar(self) -> Scalar:
        return self.mass_

    def mass(self, q: Vector) -> Matrix:
        return natural_mass_matrix(self.mass_, self.inertia)

    def force(self, q: Vector, v: Vector, t: Scalar) -> Vector:
        return jnp.zeros_like(q).at[2].set(-self.mass_ * self.gravity)

    def bilateral(self, q: Vector) -> jax.Array:
        return rigidity_constraints(q, self.size)

    def unilateral(self, q: Vector) -> jax.Array:
        if not self.contact:
            return jnp.zeros((0,), q.dtype)
        return point_heights(q, self.points) - self.floor_z

    @property
    def restitution(self) -> jax.Array:
        return self.e if self.contact else jnp.zeros((0,), self.e.dtype)

    # ------------------------------------------------------------ observables
    def rotation(self, q: Vector) -> Matrix:
        """Rotation matrix R = [u v w] (3, 3)."""
        return frame(q)

    def angular_velocity(self, q: Vector, v: Vector) -> Vector:
        """Spatial angular velocity ω (3,) [rad/s]."""
        return angular_velocity(q, v)

    def point_velocity(self, q: Vector, v: Vector, X: Vector) -> Vector:
        """Velocity (3,) of the material point X: x is linear in q, so ẋ = x(q̇) - x(0)."""
        return v[:3] + frame(v) @ X

    def angular_speed(self, q: Vector, v: Vector) -> float:
        """|ω| [rad/s]."""
        return float(jnp.linalg.norm(angular_velocity(q, v)))

    def energy(self, q: Vector, v: Vector) -> Scalar:
        """Kinetic + gravitational potential energy [J]."""
        return 0.5 * v @ self.mass(q) @ v + self.mass_ * self.gravity * q[2]

    def angular_momentum(self, q: Vector, v: Vector) -> Vector:
        """Angular momentum about the origin (3,) [kg m²/s]: m r × ṙ + Σ_ij S_ij u_i × u̇_j."""
        S = second_moments(self.inertia)
        R, Rdot = frame(q), frame(v)
        spin = jnp.einsum("ij,ki,lj,mkl->m", S, R, Rdot, _levi_civita(S.dtype))
        return self.mass_ * jnp.cross(q[:3], v[:3]) + spin


def _levi_civita(dtype) -> jax.Array:
    eps = jnp.zeros((3, 3, 3), dtype)
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        eps = eps.at[i, j, k].set(1.0).at[i, k, j].set(-1.0)
    return eps
