"""Joints between 3D rigid bodies (or a 3D rigid body and the ground).

A spherical joint is :class:`~nsga_jax.system.Pin` in 3 dimensions. The
joints here also hold orientations: each body's frame is its rotation matrix
R (:meth:`~nsga_jax.system.RigidBody3D.rotation`; the identity for the
ground), affine in natural coordinates. Their angular constraints are dot
products of unit vectors (≈ small angles [rad]) multiplied by ``scale`` [m],
so that every row of g_q is of the scale of the rigidity constraints.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._custom_types import Matrix, Scalar, Vector
from .._util import as_float
from .._validation import POSITIVE
from .base import AbstractBody, Ground
from .joints import AbstractTwoPointJoint


def body_rotation(body: AbstractBody, q: Vector) -> Matrix:
    """A 3D body's rotation matrix (3, 3) (body frame to world); the identity for the ground."""
    if isinstance(body, Ground):
        return jnp.eye(3, dtype=q.dtype)
    return body.rotation(q)  # type: ignore[attr-defined]


def perpendiculars(axis: Vector) -> tuple[Vector, Vector]:
    """Two unit vectors (each (3,)) that make a right-handed orthonormal
    triple with the normalised ``axis`` (3,)."""
    n = axis / jnp.linalg.norm(axis)
    helper = jnp.eye(3, dtype=n.dtype)[jnp.argmin(jnp.abs(n))]  # the coordinate axis least aligned with n
    p1 = jnp.cross(n, helper)
    p1 = p1 / jnp.linalg.norm(p1)
    return p1, jnp.cross(n, p1)


def _oriented_rule(bodies: tuple[AbstractBody, ...], joint: str) -> str | None:
    for side, b in zip("ab", bodies):
        if b.dim != 3:
            return f"a {joint} joins bodies in 3 dimensions; body {side} lives in {b.dim}"
        if not (isinstance(b, Ground) or hasattr(b, "rotation")):
            return f"body {side} ({type(b).__name__}) has no orientation (a 3D rigid body or the ground)"
    return None


def _axis_rule(name: str, value) -> str | None:
    a = np.asarray(value)
    if a.shape != (3,) or not np.linalg.norm(a) > 0:
        return f"{name} must be a non-zero vector of 3 coordinates, got {a.tolist()}"
    return None


class Revolute(AbstractTwoPointJoint):
    """A 3D hinge: the anchor points coincide and the hinge axis of body a
    stays aligned with that of body b; the bodies turn freely about it.

    Five constraints: ``x_a - x_b`` (3) [m], and ``scale (R_a n_a) · (R_b p_i)``
    (2) [m] with p_1, p_2 (:func:`perpendiculars`) perpendicular to b's axis n_b.

    Attributes:
        axis: the hinge axis n_a (3,) in body a's frame (world coordinates
            when a is the ground); normalised at evaluation.
        axis_b: the hinge axis n_b (3,) in body b's frame (``None``: the same
            components as ``axis``, as where the two frames coincide at assembly).
        scale: length [m] multiplying the two angular constraints.
    """

    axis: Vector = eqx.field(converter=as_float, kw_only=True)
    axis_b: Vector | None = eqx.field(converter=lambda x: None if x is None else as_float(x), default=None,
                                      kw_only=True)
    scale: Scalar = eqx.field(converter=as_float, default=1.0, kw_only=True)
    ranges = {"scale": POSITIVE}

    def invalid(self) -> str | None:
        return _axis_rule("axis", self.axis) or (None if self.axis_b is None else _axis_rule("axis_b", self.axis_b))

    def count(self, bodies) -> int:
        return 5

    def evaluate(self, bodies, qs):
        xa, xb = self.points(bodies, qs)
        dtype = qs[0].dtype
        axis_a = self.axis.astype(dtype)
        axis_b = axis_a if self.axis_b is None else self.axis_b.astype(dtype)
        n = body_rotation(bodies[0], qs[0]) @ (axis_a / jnp.linalg.norm(axis_a))
        Rb = body_rotation(bodies[1], qs[1])
        p1, p2 = perpendiculars(axis_b)
        aligned = self.scale.astype(dtype) * jnp.stack([n @ (Rb @ p1), n @ (Rb @ p2)])
        return jnp.concatenate([xa - xb, aligned])

    def is_linear(self, bodies) -> bool:
        # R is affine in natural coordinates: the products are affine where one side is fixed
        return all(b.linear_points for b in bodies) and any(b.n_dof == 0 for b in bodies)

    def invalid_on(self, bodies) -> str | None:
        return _oriented_rule(bodies, "revolute joint") or super().invalid_on(bodies)


class Weld3D(AbstractTwoPointJoint):
    """A 3D weld (clamp): the anchor points coincide and body b's frame keeps
    the orientation ``rotation`` relative to body a's: ``R_b = R_a R_rel``.

    Six constraints: ``x_a - x_b`` (3) [m] and ``scale [f1·b2, f2·b3, f3·b1]``
    (3) [m], with f_i the columns of ``R_a R_rel`` and b_i those of R_b (the
    three small angles of the relative rotation, up to sign).

    Attributes:
        rotation: R_rel (3, 3), b's frame in a's (``None``: the identity).
        scale: length [m] multiplying the three angular constraints.
    """

    rotation: Matrix = eqx.field(converter=lambda x: jnp.eye(3) if x is None else as_float(x), default=None,
                                 kw_only=True)
    scale: Scalar = eqx.field(converter=as_float, default=1.0, kw_only=True)
    ranges = {"scale": POSITIVE}

    def invalid(self) -> str | None:
        R = np.asarray(self.rotation)
        if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or not np.linalg.det(R) > 0:
            return f"rotation must be a (3, 3) rotation matrix, got {R.tolist()}"
        return None

    def count(self, bodies) -> int:
        return 6

    def evaluate(self, bodies, qs):
        xa, xb = self.points(bodies, qs)
        dtype = qs[0].dtype
        F = body_rotation(bodies[0], qs[0]) @ self.rotation.astype(dtype)
        B = body_rotation(bodies[1], qs[1])
        turned = jnp.stack([F[:, 0] @ B[:, 1], F[:, 1] @ B[:, 2], F[:, 2] @ B[:, 0]])
        return jnp.concatenate([xa - xb, self.scale.astype(dtype) * turned])

    def is_linear(self, bodies) -> bool:
        return all(b.linear_points for b in bodies) and any(b.n_dof == 0 for b in bodies)

    def invalid_on(self, bodies) -> str | None:
        return _oriented_rule(bodies, "weld") or super().invalid_on(bodies)

