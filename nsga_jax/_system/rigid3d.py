"""A 3D rigid body of a system, in natural coordinates.

Coordinates q = [r, u, v, w] (12,): the centre of mass r [m] and the
columns u, v, w of the rotation matrix R from the body frame to the world
(:mod:`nsga_jax._elements.rigid_body`). A material point with body
coordinates X (3,) is at ``r + X1 u + X2 v + X3 w``, affine in q; the mass
matrix is constant and rigidity is the body's six quadratic bilateral
constraints, scaled by a characteristic length ``size`` so that they read
as displacements [m].
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Matrix, Scalar, Vector
from .._elements.rigid_body import (
    angular_velocity,
    frame,
    natural_mass_matrix,
    natural_velocities,
    rigidity_constraints,
    second_moments,
)
from .._util import as_float
from .._validation import POSITIVE
from .base import AbstractBody


def _inertia_tensor(inertia) -> jax.Array:
    """A (3, 3) tensor from a tensor or from 3 principal values (a diagonal tensor)."""
    J = as_float(inertia)
    return jnp.diag(J) if J.ndim == 1 else J


def default_size(mass, inertia) -> jax.Array:
    """``sqrt(1.5 tr(J) / m)`` [m]: for a homogeneous box the half of its
    diagonal, ``|sides| / 2`` (the distance from the centre to a vertex); for
    any body the half-diagonal of the box with its mass and inertia."""
    return jnp.sqrt(1.5 * jnp.trace(_inertia_tensor(inertia)) / as_float(mass))


class RigidBody3D(AbstractBody):
    """A rigid body in 3 dimensions, in natural coordinates (12 coordinates,
    6 rigidity constraints of its own, constant mass matrix).

    Anchors ``at`` are body-frame coordinates (3,) [m] relative to the centre
    of mass. The body's orientation is :meth:`rotation` (for 3D joints).

    Args:
        mass: m [kg].
        inertia: the inertia tensor at the centre of mass (3, 3) [kg m²], in
            the body frame, or its 3 principal values (a diagonal tensor).
            The principal values must satisfy the triangle inequality
            strictly (a flat body has a singular mass matrix in these
            coordinates).
        position: initial centre of mass (3,) [m].
        rotation: initial rotation matrix R0 (3, 3) from the body frame to
            the world (``None``: the identity).
        velocity: initial velocity of the centre of mass (3,) [m/s].
        angular_velocity: initial angular velocity (3,) [rad/s], in world
            (spatial) coordinates.
        size: characteristic length [m] multiplying the rigidity
            constraints (``None``: :func:`default_size`, the half-diagonal of
            the equivalent box).
    """

    mass_: Scalar = eqx.field(converter=as_float)
    inertia: Matrix = eqx.field(converter=_inertia_tensor)
    position0: Vector = eqx.field(converter=as_float)
    rotation0: Matrix = eqx.field(converter=as_float)
    velocity0: Vector = eqx.field(converter=as_float)
    angular_velocity0: Vector = eqx.field(converter=as_float)
    size: Scalar = eqx.field(converter=as_float)

    ranges = {"mass_": POSITIVE, "size": POSITIVE}

    def __init__(self, mass, inertia, position, rotation=None, velocity=(0.0, 0.0, 0.0),
                 angular_velocity=(0.0, 0.0, 0.0), size=None):
        self.mass_, self.inertia = as_float(mass), _inertia_tensor(inertia)
        self.position0 = as_float(position)
        self.rotation0 = jnp.eye(3) if rotation is None else as_float(rotation)
        self.velocity0, self.angular_velocity0 = as_float(velocity), as_float(angular_velocity)
        self.size = default_size(mass, self.inertia) if size is None else as_float(size)

    def invalid(self) -> str | None:
        for name, value in (("position", self.position0), ("velocity", self.velocity0),
                            ("angular_velocity", self.angular_velocity0)):
            if np.shape(value) != (3,):
                return f"{name} must be a vector of 3 coordinates, got shape {np.shape(value)}"
        J = np.asarray(self.inertia)
        if J.shape != (3, 3) or not np.allclose(J, J.T, rtol=1e-12, atol=0.0):
            return f"inertia must be 3 principal values or a symmetric (3, 3) tensor [kg m^2], got {J.tolist()}"
        moments = np.linalg.eigvalsh(0.5 * np.trace(J) * np.eye(3) - J)  # second_moments, in NumPy
        if np.linalg.eigvalsh(J).min() <= 0 or moments.min() <= 0:
            return (f"inertia must be positive definite with principal values obeying the triangle inequality "
                    f"strictly (J1 < J2 + J3, ...; a flat body has a singular mass matrix), got eigenvalues "
                    f"{np.linalg.eigvalsh(J).tolist()}")
        R = np.asarray(self.rotation0)
        if R.shape != (3, 3) or not np.linalg.det(R) > 0:
            return f"rotation must be a (3, 3) rotation matrix (determinant +1), got {R.tolist()}"
        return None

    dim = 3  # type: ignore[assignment]
    n_dof = 12  # type: ignore[assignment]
    n_bilateral = 6  # type: ignore[assignment]

    @property
    def total_mass(self) -> Scalar:
        return self.mass_

    def initial_state(self) -> tuple[Vector, Vector]:
        R0 = self.rotation0
        q0 = jnp.concatenate([self.position0, R0[:, 0], R0[:, 1], R0[:, 2]])
        return q0, natural_velocities(R0, self.angular_velocity0, self.velocity0)

    def mass(self, q: Vector) -> Matrix:
        return natural_mass_matrix(self.mass_, self.inertia).astype(q.dtype)

    def gravity_force(self, g: Vector) -> Vector:
        return jnp.concatenate([self.mass_ * g, jnp.zeros((9,), g.dtype)])

    def bilateral(self, q: Vector) -> Vector:
        return rigidity_constraints(q, self.size.astype(q.dtype))

    def position(self, q: Vector, at: Vector, node: int | None) -> Vector:
        # r + Σ_i X_i e_i elementwise: on the CPU a small dot is a kernel of its
        # own (see rigidity_constraints), and a vertex set is vmapped over this
        frame_rows = q[3:12].reshape(3, 3)  # u, v, w
        return q[:3] + jnp.sum(at.astype(q.dtype)[:, None] * frame_rows, axis=0)

    def rotation(self, q: Vector) -> Matrix:
        """R = [u v w] (3, 3): body frame to world (orthonormal where the
        rigidity constraints hold; affine in q)."""
        return frame(q)

    def angular_velocity(self, q: Vector, v: Vector) -> Vector:
        """Spatial angular velocity ω (3,) [rad/s]."""
        return angular_velocity(q, v)

    def angular_speed(self, q: Vector, v: Vector) -> Scalar:
        return jnp.linalg.norm(angular_velocity(q, v))

    def angular_momentum(self, q: Vector, v: Vector) -> Vector:
        """Angular momentum about the world origin (3,) [kg m²/s]:
        ``m r × ṙ + Σ_ij S_ij u_i × u̇_j`` (S the second moments)."""
        S = second_moments(self.inertia).astype(q.dtype)
        R, Rdot = frame(q), frame(v)
        spin = sum((S[i, j] * jnp.cross(R[:, i], Rdot[:, j]) for i in range(3) for j in range(3)),
                   jnp.zeros((3,), q.dtype))
        return self.mass_ * jnp.cross(q[:3], v[:3]) + spin
