"""Rigid body in natural coordinates.

Coordinates q = [r, u, v, w] (12,): the centre of mass r [m] and the three
body-fixed unit vectors u, v, w (the columns of the rotation matrix R). A
material point with body coordinates X (relative to the centre of mass, in the
body frame) is at ``x = r + X1 u + X2 v + X3 w``: linear in q. Hence the mass
matrix is constant, ``M = diag(m I3, S ⊗ I3)`` with the second moments
``S = ∫ ρ X Xᵀ dV = tr(J)/2 I - J`` (J the inertia tensor at the centre of
mass), and rigidity is six quadratic bilateral constraints. Gyroscopic effects
come from these constraints; no rotation parametrisation is needed, so the
vector-space scheme applies as written.
"""

from __future__ import annotations

from typing import cast

import jax
import jax.numpy as jnp
import numpy as np


def second_moments(inertia: jax.Array) -> jax.Array:
    """S = tr(J)/2 I - J, shape (3, 3) [kg m²], from the inertia tensor J (3, 3)."""
    return 0.5 * jnp.trace(inertia) * jnp.eye(3, dtype=inertia.dtype) - inertia


def natural_mass_matrix(mass: jax.Array, inertia: jax.Array) -> jax.Array:
    """Constant mass matrix (12, 12) of a rigid body in natural coordinates."""
    S = second_moments(inertia)
    real = jnp.result_type(mass, inertia)  # the body's precision
    M = jnp.zeros((12, 12), real)
    M = M.at[:3, :3].set(mass * jnp.eye(3, dtype=real))
    return M.at[3:, 3:].set(jnp.kron(S, jnp.eye(3, dtype=real)))


def frame(q: jax.Array) -> jax.Array:
    """Rotation matrix R = [u v w], shape (3, 3)."""
    return jnp.stack([q[3:6], q[6:9], q[9:12]], axis=1)


def point_position(q: jax.Array, X: jax.Array) -> jax.Array:
    """Position (3,) of the material point with body coordinates X (3,)."""
    return q[:3] + frame(q) @ X


_FIRST = np.array([0, 1, 2, 0, 1, 2])  # the constraints' pairs of unit vectors:
_SECOND = np.array([0, 1, 2, 1, 2, 0])  # (u,u) (v,v) (w,w) (u,v) (v,w) (w,u)
_NORMS = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])  # 1 for the three norms
_HALF = np.array([0.5, 0.5, 0.5, 1.0, 1.0, 1.0])


def rigidity_constraints(q: jax.Array, length: jax.Array) -> jax.Array:
    """Six rigidity constraints (6,) [m]: ``length * [(u·u-1)/2, (v·v-1)/2,
    (w·w-1)/2, u·v, v·w, w·u]``. ``length`` (a characteristic size of the
    body) turns them into displacements of a material point at that distance.

    Written as one elementwise product and a sum rather than six dot products:
    on the CPU every small ``dot`` (and each of its derivatives) is a kernel
    of its own, which doubled the rigid box's step time and compile time."""
    frame_rows = q[3:12].reshape(3, 3)  # u, v, w
    products = jnp.sum(frame_rows[_FIRST] * frame_rows[_SECOND], axis=1)
    half, norms = (jnp.asarray(c, products.dtype) for c in (_HALF, _NORMS))  # in q's precision
    return length * half * (products - norms)


def point_heights(q: jax.Array, X: jax.Array) -> jax.Array:
    """z of the material points with body coordinates X (P, 3), shape (P,) [m]
    (elementwise, for the reason given in :func:`rigidity_constraints`)."""
    return q[2] + jnp.sum(X * q[5:12:3], axis=-1)  # z + X1 u_z + X2 v_z + X3 w_z


def angular_velocity(q: jax.Array, qdot: jax.Array) -> jax.Array:
    """Spatial angular velocity ω (3,) [rad/s] from ``u̇ = ω × u`` etc.:
    ``ω = ½ Σ_i u_i × u̇_i`` for an orthonormal frame."""
    # a sum of three arrays: never the empty sum's 0
    return 0.5 * cast(jax.Array, sum(jnp.cross(q[3 * i:3 * i + 3], qdot[3 * i:3 * i + 3]) for i in (1, 2, 3)))


def natural_velocities(R: jax.Array, omega: jax.Array, v_com: jax.Array) -> jax.Array:
    """q̇ (12,) from the rotation matrix R, the spatial angular velocity ω and the
    centre-of-mass velocity: ``[v, ω × u, ω × v, ω × w]``."""
    return jnp.concatenate([v_com] + [jnp.cross(omega, R[:, i]) for i in range(3)])


def box_inertia(mass: jax.Array, sides: jax.Array) -> jax.Array:
    """Inertia tensor (3, 3) of a homogeneous box with side lengths (3,) about its centre."""
    lx, ly, lz = sides[0], sides[1], sides[2]
    return mass / 12.0 * jnp.diag(jnp.stack([ly**2 + lz**2, lx**2 + lz**2, lx**2 + ly**2]))


def box_vertices(sides: jax.Array) -> jax.Array:
    """Body coordinates (8, 3) of the vertices of a box centred at its centre of mass.

    Order: bits (i, j, k) of the vertex index select -/+ along x, y, z
    (vertex 0 is (-,-,-), vertex 7 is (+,+,+))."""
    signs = jnp.array([[(k >> 0) & 1, (k >> 1) & 1, (k >> 2) & 1] for k in range(8)], dtype=float) * 2 - 1
    return 0.5 * signs * sides
