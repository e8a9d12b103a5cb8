"""Iteration matrices of large models, never assembled: preconditioned
conjugate gradients on element-by-element products (paper eqs. 47-49).

A model that is ``matrix_free`` (:attr:`~nsga_jax.models.Model.matrix_free`)
gives its iteration matrices' top-left blocks as element blocks
(:class:`~nsga_jax.assembly.ElementMatrix`, A = c_m M + c_k K element by
element) and its constraint rows as node-local rows
(:class:`~nsga_jax.assembly.NodeRows`). A Newton correction then solves with
A by conjugate gradients (``jax.scipy.sparse.linalg.cg``, whose derivatives
are those of the linear solve, one more solve each), preconditioned by A's
diagonal: the blocks are dominated by the mass at the steps the scheme
takes, and the Jacobi-scaled mass of trilinear hexahedra has a condition
number below 30 whatever the mesh, so the iterations do not grow with n.

A bordered correction (:mod:`~nsga_jax.integrators.linalg`) with
orthonormal active rows G_a (one contact per node, unit normals) is solved
exactly by projection: with P = I - G_aᵀ G_a,

    dx = G_aᵀ r2_a / k + z,   P A P z = -P (r1 + A G_aᵀ r2_a / k),
    dμ_a = G_a (A dx + r1) / k + (p/k²) r2_a,   dμ_ā = (p/k²) r2_ā,

which is what :func:`~nsga_jax.integrators.linalg.solve_bordered` gives, by
one conjugate-gradient solve on the range of P whatever the number of
active contacts (no Schur complement is formed).

**Tolerance.** Each solve stops at ||A d - b|| <= η ||b|| with
η = max(κ tol_r, 64 eps), κ = 0.1: in a Newton update b is the residual,
whose norm is at most the sum of the terms of eq. 51's bound, so the linear
error of an update is at most a tenth of the convergence test, and Newton,
which evaluates the residual exactly, ends on an iterate that passes eq. 51
as the dense path's does.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.sparse.linalg as jsp

from .._custom_types import ActiveSet, Scalar, Vector
from ..assembly import ElementMatrix, NodeRows
from ..models.base import Model
from .iteration_matrix import AbstractIterationMatrix, BuildElements, BuildMatrix
from .linalg import AbstractFactorisation
from .model_terms import ElementMass

KAPPA = 0.1
"""A linear solve's residual relative to eq. 51's bound (see the module docstring)."""

KRYLOV_MIN_DOF: int | None = None
"""The size from which DS solves a matrix-free model without assembling
(:attr:`~nsga_jax.integrators.ds.DS.krylov_min_dof`); ``None``: only when asked."""

MAX_STEPS = 1000
"""The most conjugate-gradient steps of one solve (a mass-dominated block needs 20-70)."""

def linear_tolerance(tol_r, dtype) -> jax.Array:
    """η = max(κ tol_r, 64 eps): the relative residual each linear solve stops at."""
    return jnp.maximum(KAPPA * jnp.asarray(tol_r, dtype), 64 * jnp.finfo(dtype).eps)


def cg(matvec: Callable[[Vector], Vector], b: Vector, precondition: Callable[[Vector], Vector],
       rtol: Scalar) -> Vector:
    """x with ||matvec(x) - b|| <= rtol ||b|| by preconditioned conjugate
    gradients (``jax.scipy.sparse.linalg.cg``: differentiable as a linear solve)."""
    x, _ = jsp.cg(matvec, b, tol=jax.lax.stop_gradient(rtol), atol=0.0, maxiter=MAX_STEPS, M=precondition)
    return x


class KrylovOperator(AbstractFactorisation):
    """A top-left block A as element blocks, solved by preconditioned conjugate gradients.

    Attributes:
        A: the block, :class:`~nsga_jax.assembly.ElementMatrix` (n × n, never assembled).
        inverse_diagonal: 1 / diag(A), shape (n,) (the preconditioner).
        rtol: η, the relative residual each solve stops at (:func:`linear_tolerance`).
        K_norm, C_norm: Frobenius norms of the tangents A was built from (round-off floor).
    """

    A: ElementMatrix
    inverse_diagonal: Vector
    rtol: Scalar
    K_norm: Scalar
    C_norm: Scalar

    @classmethod
    def of(cls, A: ElementMatrix, K_norm: Scalar, C_norm: Scalar, rtol: Scalar) -> "KrylovOperator":
        return cls(A=A, inverse_diagonal=1.0 / A.diagonal(), rtol=rtol, K_norm=K_norm, C_norm=C_norm)

    def solve(self, rhs: jax.Array) -> jax.Array:
        """``A^{-1} rhs`` for rhs (n,) (or (n, m): one solve per column)."""
        if rhs.ndim == 2:
            return jax.vmap(self.solve, in_axes=1, out_axes=1)(rhs)
        return cg(self.A.mv, rhs, lambda r: self.inverse_diagonal * r, self.rtol)

    def bordered(self, r1: Vector, r2: jax.Array, G_up, G_low, active: ActiveSet, k: Scalar,
                 p: Scalar) -> tuple[Vector, jax.Array]:
        """The bordered correction (dx, dμ) by projection on the inactive
        coordinates (module docstring); the rows must be orthonormal
        :class:`~nsga_jax.assembly.NodeRows` (checked when the run is prepared)."""
        if not isinstance(G_up, NodeRows) or G_up is not G_low:
            return super().bordered(r1, r2, G_up, G_low, active, k, p)
        G = NodeRows(jnp.where(active[:, None], G_up.vals, 0.0), G_up.cols, G_up.n)  # G_a, zero rows inactive

        def project(x):  # P x = x - G_aᵀ G_a x
            return x - G.T @ (G @ x)

        fixed = G.T @ (jnp.where(active, r2, 0.0) / k)
        b = project(-r1 - self.A.mv(fixed))
        def on_range(apply):  # P B P + (I - P): SPD, and P B P on the range of P
            return lambda x: project(apply(project(x))) + (x - project(x))

        z = cg(on_range(self.A.mv), b, on_range(lambda r: self.inverse_diagonal * r), self.rtol)
        dx = fixed + project(z)
        dmu = jnp.where(active, (G @ (self.A.mv(dx) + r1)) / k, 0.0) + (p / k**2) * r2
        return dx, dmu


class KrylovFresh(AbstractIterationMatrix):
    """A evaluated as element blocks at every Newton iteration and solved by
    conjugate gradients (:class:`KrylovOperator`).

    Attributes:
        rtol: η, the relative residual each solve stops at.
    """

    rtol: Scalar
    is_constant: ClassVar[bool] = False

    def factored(self, build: BuildMatrix, elements: BuildElements | None = None) -> AbstractFactorisation:
        assert elements is not None, "a matrix-free sub-problem gives its block as element blocks"
        return KrylovOperator.of(*elements(), rtol=self.rtol)


class KrylovConstant(AbstractIterationMatrix):
    """A constant A (constant mass, linear force) as element blocks, built
    once per step size and solved by conjugate gradients.

    Attributes:
        operator: the block and its preconditioner (:class:`KrylovOperator`).
    """

    operator: KrylovOperator
    is_constant: ClassVar[bool] = True

    def factored(self, build: BuildMatrix, elements: BuildElements | None = None) -> AbstractFactorisation:
        return self.operator


def element_top_left(model: Model, ops, q: Vector, c_m, c_k) -> tuple[ElementMatrix, Scalar, Scalar]:
    """``c_m M + c_k K(q)`` as element blocks, with ||K|| and ||C|| = 0 (the
    round-off floor): a matrix-free sub-problem's top-left block (eqs. 47-49
    with a constant mass, affine constraints and no damping)."""
    assert isinstance(ops.mass, ElementMass), "element blocks need a matrix-free model's operators"
    K = model.element_stiffness(q)
    return ops.mass.M.combine(c_m, K, c_k), K.frobenius_norm(), jnp.zeros((), q.dtype)


KRYLOV_KINDS = (KrylovFresh, KrylovConstant)
"""The kinds of iteration matrices that are never assembled."""
