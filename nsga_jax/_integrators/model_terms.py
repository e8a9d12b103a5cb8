"""The model's terms as the Newton sub-problems use them: mass, force and
constraint Jacobian, each either constant (evaluated once per run, from the
model's structure flags) or evaluated at the state.

Which kind a run uses is decided at trace time by
:func:`~nsga_jax._integrators.operators.prepare_operators`; every kind has the
same methods, so the sub-problems (:mod:`~nsga_jax._integrators.subproblems`)
read the same whatever the structure. The methods take the model: a term
object holds only what the model's structure makes constant.
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._blocks import KroneckerMass, NodeBlockMatrix, NodeRows
from .._custom_types import Matrix, Scalar, Vector
from .._models.base import Model
from .linalg import band_product, saddle_acceleration

# ------------------------------------------------------------------------- mass


class AbstractMass(eqx.Module):
    """The mass matrix M(q), shape (n, n) [kg, or kg m² on rotations].

    Class attribute ``is_constant``: M is the same at every q (known at trace time).
    """

    is_constant: ClassVar[bool]

    @abc.abstractmethod
    def matrix(self, model: Model, q: Vector) -> Matrix:
        """M(q), shape (n, n)."""

    @abc.abstractmethod
    def product(self, model: Model, q: Vector, x: Vector) -> Vector:
        """M(q) @ x, shape (n,)."""

    @abc.abstractmethod
    def norm(self, model: Model, q: Vector) -> Scalar:
        """Frobenius norm ||M(q)|| (for the round-off floor)."""

    def diagonal(self, model: Model, q: Vector) -> Vector:
        """The diagonal of M(q), shape (n,) (friction's tangential penalties)."""
        return jnp.diagonal(self.matrix(model, q))


class VaryingMass(AbstractMass):
    """M(q) evaluated at every state (``model.mass``, ``model.mass_product``)."""

    is_constant: ClassVar[bool] = False

    def matrix(self, model: Model, q: Vector) -> Matrix:
        return model.mass(q)

    def product(self, model: Model, q: Vector, x: Vector) -> Vector:
        return model.mass_product(q, x)

    def norm(self, model: Model, q: Vector) -> Scalar:
        return jnp.linalg.norm(model.mass(q))


class ConstantMass(AbstractMass):
    """A constant M, evaluated once; products stay the model's own
    (element by element, cheaper than a dense product).

    Attributes:
        M: the mass matrix, shape (n, n).
        M_norm: its Frobenius norm.
    """

    M: Matrix
    M_norm: Scalar
    is_constant: ClassVar[bool] = True

    def matrix(self, model: Model, q: Vector) -> Matrix:
        return self.M

    def product(self, model: Model, q: Vector, x: Vector) -> Vector:
        return model.mass_product(q, x)

    def norm(self, model: Model, q: Vector) -> Scalar:
        return self.M_norm


class ElementMass(AbstractMass):
    """A constant M kept as element blocks (a matrix-free model), never assembled.

    Attributes:
        M: the mass matrix as node blocks (:class:`~nsga_jax._blocks.NodeBlockMatrix`, n × n).
        M_norm: its Frobenius norm.
        kronecker: M as a Kronecker product where the model has one
            (:meth:`~nsga_jax._models.Model.kronecker_mass`), else ``None``:
            its products then skip the node blocks, and its exact inverse
            preconditions the iteration matrices.
    """

    M: NodeBlockMatrix
    M_norm: Scalar
    kronecker: KroneckerMass | None = None
    is_constant: ClassVar[bool] = True

    def matrix(self, model: Model, q: Vector) -> Matrix:
        raise TypeError("a matrix-free model's mass is never assembled")

    def diagonal(self, model: Model, q: Vector) -> Vector:
        return self.M.diagonal()

    def product(self, model: Model, q: Vector, x: Vector) -> Vector:
        return self.M.mv(x) if self.kronecker is None else self.kronecker.mv(x)

    def norm(self, model: Model, q: Vector) -> Scalar:
        return self.M_norm


class BandedMass(AbstractMass):
    """A constant banded M (:func:`~nsga_jax._integrators.operators.banded`),
    whose products are taken on its band.

    Attributes:
        M: the mass matrix, shape (n, n).
        M_norm: its Frobenius norm.
        band: its 2b + 1 diagonals, shape (2b + 1, n) (:func:`~nsga_jax._integrators.linalg.band_matrix`).
    """

    M: Matrix
    M_norm: Scalar
    band: jax.Array
    is_constant: ClassVar[bool] = True

    def matrix(self, model: Model, q: Vector) -> Matrix:
        return self.M

    def product(self, model: Model, q: Vector, x: Vector) -> Vector:
        return band_product(self.band, x)

    def norm(self, model: Model, q: Vector) -> Scalar:
        return self.M_norm


# ------------------------------------------------------------------------ force


class ForceAt(NamedTuple):
    """The force f = f(q, v, t) [N] evaluated at one point (q, v) at the step's time t."""

    q: Vector
    v: Vector
    f: Vector


def force_at(model: Model, q: Vector, v: Vector, t: Scalar) -> ForceAt:
    return ForceAt(q, v, model.force(q, v, t))


class AbstractForceTerm(eqx.Module):
    """The applied and internal force f(q, v, t), shape (n,) [N], and its
    tangents K = -∂f/∂q [N/m] and C = -∂f/∂v [N s/m], shape (n, n).

    Class attribute ``is_constant``: K and C are the same at every state
    (a linear force; known at trace time).
    """

    is_constant: ClassVar[bool]

    @abc.abstractmethod
    def tangents(self, model: Model, q: Vector, v: Vector, t: Scalar) -> tuple[Matrix, Matrix, Scalar, Scalar]:
        """K, C and their Frobenius norms (for the round-off floor); C = 0
        for a force that does not depend on v."""

    def reference(self, model: Model, q: Vector, v: Vector, t: Scalar) -> ForceAt | None:
        """The force at (q, v) when :meth:`near` needs it (a banded linear
        force), else ``None`` (:meth:`near` evaluates f itself)."""
        return None

    def change(self, model: Model, ref: ForceAt, q: Vector, v: Vector, t: Scalar) -> Vector:
        """f(q, v, t) - ref.f at the same time t. Evaluating f (element
        assembly, O(n)) is cheaper than a dense tangent product; the round-off
        it leaves is what the Newton floor covers."""
        return model.force(q, v, t) - ref.f

    def near(self, model: Model, ref: ForceAt | None, q: Vector, v: Vector, t: Scalar) -> Vector:
        """f(q, v, t), from ``ref`` (:meth:`reference`) where that is cheaper."""
        return model.force(q, v, t)


class NonlinearForce(AbstractForceTerm):
    """Tangents evaluated at every state (``model.tangents``)."""

    is_constant: ClassVar[bool] = False

    def tangents(self, model: Model, q: Vector, v: Vector, t: Scalar) -> tuple[Matrix, Matrix, Scalar, Scalar]:
        K, C = model.tangents(q, v, t)
        if not model.velocity_dependent_force:
            C = jnp.zeros_like(K)
        return K, C, jnp.linalg.norm(K), jnp.linalg.norm(C)


class LinearForce(AbstractForceTerm):
    """A force affine in (q, v): constant K and C, evaluated once.

    Attributes:
        K, C: stiffness and damping, shape (n, n) (C = 0 without velocity dependence).
        K_norm, C_norm: their Frobenius norms.
    """

    K: Matrix
    C: Matrix
    K_norm: Scalar
    C_norm: Scalar
    is_constant: ClassVar[bool] = True

    def tangents(self, model: Model, q: Vector, v: Vector, t: Scalar) -> tuple[Matrix, Matrix, Scalar, Scalar]:
        return self.K, self.C, self.K_norm, self.C_norm


class BandedLinearForce(AbstractForceTerm):
    """A linear force with banded K and C: differences of f are taken
    exactly on the band, -K (q - ref.q) - C (v - ref.v), O(b n).

    Attributes:
        K, C, K_norm, C_norm: as :class:`LinearForce`.
        K_band, C_band: the 2b + 1 diagonals of K and C, shape (2b + 1, n)
            (C's only for a velocity-dependent force, else ``None``).
        velocity_dependent: whether C enters the differences (static).
    """

    K: Matrix
    C: Matrix
    K_norm: Scalar
    C_norm: Scalar
    K_band: jax.Array
    C_band: jax.Array | None
    velocity_dependent: bool = eqx.field(static=True)
    is_constant: ClassVar[bool] = True

    def tangents(self, model: Model, q: Vector, v: Vector, t: Scalar) -> tuple[Matrix, Matrix, Scalar, Scalar]:
        return self.K, self.C, self.K_norm, self.C_norm

    def reference(self, model: Model, q: Vector, v: Vector, t: Scalar) -> ForceAt | None:
        return force_at(model, q, v, t)

    def change(self, model: Model, ref: ForceAt, q: Vector, v: Vector, t: Scalar) -> Vector:
        df = -band_product(self.K_band, q - ref.q)
        if self.velocity_dependent:
            assert self.C_band is not None  # kept for a velocity-dependent force
            df = df - band_product(self.C_band, v - ref.v)
        return df

    def near(self, model: Model, ref: ForceAt | None, q: Vector, v: Vector, t: Scalar) -> Vector:
        assert ref is not None  # from reference(), which always gives one here
        return ref.f + self.change(model, ref, q, v, t)


# ---------------------------------------------------------------- constraints


class AbstractConstraintJacobian(eqx.Module):
    """The constraint Jacobian g_q(q) = d[g^B; g^U]/dq, shape (nc, n).

    Class attribute ``is_constant``: the constraints are affine, g_q is the
    same at every q (known at trace time).
    """

    is_constant: ClassVar[bool]

    @abc.abstractmethod
    def jacobian(self, model: Model, q: Vector) -> jax.Array:
        """g_q(q) for all constraints, shape (nc, n)."""

    @abc.abstractmethod
    def bilateral(self, model: Model, q: Vector) -> jax.Array:
        """g_q^B(q), shape (nb, n)."""


class VaryingJacobian(AbstractConstraintJacobian):
    """g_q(q) evaluated at every state."""

    is_constant: ClassVar[bool] = False

    def jacobian(self, model: Model, q: Vector) -> jax.Array:
        return model.constraint_jacobian(q)

    def bilateral(self, model: Model, q: Vector) -> jax.Array:
        return model.bilateral_jacobian(q)


class RowsJacobian(AbstractConstraintJacobian):
    """The constant g_q of a matrix-free model's affine constraints as
    node-local rows (:class:`~nsga_jax._blocks.NodeRows`).

    Attributes:
        G: g_q, (nc, n) as rows.
        n_bilateral: nb, its first rows being g_q^B (pinned nodes) (static).
    """

    G: NodeRows
    n_bilateral: int = eqx.field(static=True, default=0)
    is_constant: ClassVar[bool] = True

    def jacobian(self, model: Model, q: Vector) -> NodeRows:  # type: ignore[override]
        return self.G

    def bilateral(self, model: Model, q: Vector) -> jax.Array | NodeRows:  # type: ignore[override]
        if self.n_bilateral == 0:
            return jnp.zeros((0, self.G.n), q.dtype)
        return self.G.rows(0, self.n_bilateral)


class ConstantJacobian(AbstractConstraintJacobian):
    """The constant g_q of affine constraints, evaluated once.

    Attributes:
        G: g_q, shape (nc, n).
        n_bilateral: nb, its first rows being g_q^B (static).
    """

    G: jax.Array
    n_bilateral: int = eqx.field(static=True)
    is_constant: ClassVar[bool] = True

    def jacobian(self, model: Model, q: Vector) -> jax.Array:
        return self.G

    def bilateral(self, model: Model, q: Vector) -> jax.Array:
        return self.G[: self.n_bilateral]


def curvature(model: Model, q: Vector, mu: jax.Array) -> Matrix:
    """d(g_q(q)^T mu)/dq at fixed mu (mu over all nc constraints); zero if affine
    (:meth:`~nsga_jax._models.Model.constraint_curvature`)."""
    return model.constraint_curvature(q, mu)


def convective(model: Model, q: Vector, v: Vector, bilateral_only: bool = False) -> jax.Array:
    """G^s = d(g_q(q) v)/dq at fixed v, shape (nb or nc, n); zero if affine (eq. 50)."""
    return model.velocity_constraint_gradient(q, v, bilateral_only)


def pad_bilateral(model: Model, lam: jax.Array) -> jax.Array:
    """Embed a bilateral multiplier (nb,) in the full constraint space (nc,)."""
    return jnp.concatenate([lam, jnp.zeros((model.n_unilateral,), lam.dtype)])


def is_unilateral(model: Model) -> jax.Array:
    """Which constraints (nc,) are unilateral (the last nu)."""
    return jnp.arange(model.n_constraints) >= model.n_bilateral


def restitution(model: Model, dtype) -> jax.Array:
    """Restitution over all constraints (nc,), zero on the bilaterals."""
    return jnp.concatenate([jnp.zeros((model.n_bilateral,), dtype), jnp.asarray(model.restitution, dtype)])


def consistent_acceleration(model: Model, t0: Scalar, q0: Vector, v0: Vector,
                            mass_solve: Callable[[Vector], Vector] | None = None) -> Vector:
    """v̇̃_0 from the equations of motion with the bilateral constraints at
    acceleration level, unilateral constraints ignored (Algorithm 1, line 2).
    ``mass_solve``: x -> M^{-1} x where M is never assembled (a model without
    bilateral constraints).

    With G = g_q^B(q0) and the convective term c = (d(G v)/dq) v, the
    multipliers solve the Schur complement of the saddle system
    [[M, -Gᵀ], [G, 0]] (M symmetric positive definite):

        (G M⁻¹ Gᵀ) λ = -c - G M⁻¹ f,   v̇ = M⁻¹ (f + Gᵀ λ),

    with the minimum-norm λ = (G M⁻¹ Gᵀ)⁺ (-c - G M⁻¹ f) (pseudo-inverse cut
    at :func:`~nsga_jax._integrators.linalg.multiplier_rtol`). Where G has full row rank this is the
    saddle system's unique solution; where it is rank deficient (redundant
    joints, a closed loop built in 3D) v̇ is still unique and λ is the
    smallest that holds the constraints: identical rows share the load
    equally (docs/systems.md, "Redundant constraints")."""
    f = model.force(q0, v0, t0)
    nb = model.n_bilateral
    if mass_solve is not None and nb == 0:
        return mass_solve(f)
    M = model.mass(q0)
    if nb == 0:
        return jnp.linalg.solve(M, f)
    GB = jax.jacfwd(model.bilateral)(q0)
    conv = jax.jvp(lambda x: jax.jacfwd(model.bilateral)(x) @ v0, (q0,), (v0,))[1]
    return saddle_acceleration(M, f, GB, conv)[0]
