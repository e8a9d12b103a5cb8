"""Iteration matrices of large models, never assembled: preconditioned
conjugate gradients on element-by-element products (paper eqs. 47-49).

A model that is ``matrix_free`` (:attr:`~nsga_jax._models.Model.matrix_free`)
gives its iteration matrices' top-left blocks as element blocks
(:class:`~nsga_jax._blocks.ElementMatrix`, A = c_m M + c_k K element by
element, summed into node blocks) and its constraint rows as node-local
rows (:class:`~nsga_jax._blocks.NodeRows`). A Newton correction then solves
with A by conjugate gradients (``jax.scipy.sparse.linalg.cg``, whose
derivatives are those of the linear solve, one more solve each). The blocks
are dominated by the mass at the steps the scheme takes, so (c_m M)⁻¹
preconditions them well where the model has an exact M⁻¹ that costs O(n)
(:meth:`~nsga_jax._models.Model.kronecker_mass`), and A's diagonal otherwise
(the Jacobi-scaled mass of trilinear hexahedra has a condition number below
30 whatever the mesh); either way the iterations do not grow with n.

A bordered correction (:mod:`~nsga_jax._integrators.linalg`) with
orthonormal active rows G_a (one contact per node, unit normals) is solved
exactly by projection: with P = I - G_aᵀ G_a,

    dx = G_aᵀ r2_a / k + z,   P A P z = -P (r1 + A G_aᵀ r2_a / k),
    dμ_a = G_a (A dx + r1) / k + (p/k²) r2_a,   dμ_ā = (p/k²) r2_ā,

which is what :func:`~nsga_jax._integrators.linalg.solve_bordered` gives, by
one conjugate-gradient solve on the range of P whatever the number of
active contacts (no Schur complement is formed).

**Tolerance.** A Newton update's solve stops at ||A d - b|| <= κ B, κ = 0.1,
with B eq. 51's bound at the iterate (b is the residual there): the linear
error of an update is a tenth of the convergence test, so Newton, which
evaluates the residual exactly, ends on an iterate that passes eq. 51 as
the dense path's does, and a nearly linear sub-problem converges in one
update. Relative to ||b|| the tolerance is kept within [η, 0.1],
η = max(κ tol_r, 64 eps) (B >= tol_r ||b||, so η never tightens an update);
the derivative's solves (the implicit tangent at the solution,
:func:`~nsga_jax._integrators.newton.solve`) stop at η.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.sparse.linalg as jsp

from .._blocks import KroneckerMass, NodeBlockMatrix, NodeRows
from .._custom_types import ActiveSet, Scalar, ScalarLike, Vector
from .._models.base import Model
from .iteration_matrix import AbstractIterationMatrix, BuildElements, BuildMatrix
from .linalg import AbstractFactorisation
from .model_terms import ElementMass

KAPPA = 0.1
"""A linear solve's residual relative to eq. 51's bound (see the module docstring)."""

KRYLOV_MIN_DOF: int | None = 500
"""The size from which a scheme (DS, DSn, CS, MJ) solves a matrix-free model
without assembling (:attr:`~nsga_jax.DS.krylov_min_dof`), between the sizes
where the dense and matrix-free paths measured even and where the
matrix-free one is faster, on the flexible cube landing
(``experiments/benchmarks/bench_krylov.py``; the table and the switch
point are in docs/performance.md, *Cost and memory against size*)."""

MAX_FORCING = 0.1
"""The loosest relative residual of a linear solve (the first updates of a
Newton iteration far from its solution)."""

MAX_STEPS = 1000
"""The most conjugate-gradient steps of one solve (a mass-dominated block needs 20-70)."""

def linear_tolerance(tol_r: ScalarLike, dtype) -> jax.Array:
    """η = max(κ tol_r, 64 eps): the relative residual each linear solve stops at."""
    return jnp.maximum(KAPPA * jnp.asarray(tol_r, dtype), 64 * jnp.finfo(dtype).eps)


def cg(matvec: Callable[[Vector], Vector], b: Vector, precondition: Callable[[Vector], Vector],
       rtol: Scalar) -> Vector:
    """x with ||matvec(x) - b|| <= rtol ||b|| by preconditioned conjugate
    gradients (``jax.scipy.sparse.linalg.cg``: differentiable as a linear
    solve), started at the preconditioned right-hand side rather than at
    zero. Where the preconditioner nearly inverts A (the velocity jump's
    projected mass) the start is nearly the solution, and a loose forcing no
    longer leaves the Newton update short: on the cube landing at 20
    divisions the velocity jump takes 0.95 updates a step against 1.86, and
    a step 0.160-0.167 s against 0.183-0.190 from zero (three runs each,
    alternating). A single solve of the smooth block costs about the same
    from either start (``experiments/benchmarks/bench_large_kernels.py``)."""
    x, _ = jsp.cg(matvec, b, x0=precondition(b), tol=jax.lax.stop_gradient(rtol), atol=0.0, maxiter=MAX_STEPS,
                  M=precondition)
    return x


class MassPreconditioner(eqx.Module):
    """(c_m M)⁻¹ from an exact M⁻¹ (:class:`~nsga_jax._blocks.KroneckerMass`):
    the preconditioner of A = c_m M + c_k K, whose stiffness part is small
    at the steps the scheme takes (A⁻¹ exactly where c_k = 0).

    Attributes:
        mass: c_m M, with its exact inverse.
    """

    mass: KroneckerMass

    def apply(self, r: Vector) -> Vector:
        return self.mass.solve(r)


def kronecker_mass(model: Model, dtype) -> KroneckerMass | None:
    """The model's M with an exact O(n) product and inverse, in the run's precision, or ``None``."""
    mass = model.kronecker_mass()
    return None if mass is None else jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), mass)


def mass_preconditioner(mass: KroneckerMass | None, c_m) -> MassPreconditioner | None:
    """(c_m M)⁻¹ where the model has an exact M⁻¹, else ``None`` (the diagonal serves)."""
    return None if mass is None else MassPreconditioner(mass.scaled(jnp.asarray(c_m, mass.density.dtype)))


class KrylovOperator(AbstractFactorisation):
    """A top-left block A as node blocks, solved by preconditioned conjugate gradients.

    Solves are preconditioned by (c_m M)⁻¹ where the model has an exact M⁻¹
    that costs O(n), and by the diagonal otherwise; the projected bordered
    solves by the same on the range of the projection. Measured on the cube
    at 10 divisions (``P`` projected on a landed bottom face), steps to 1e-9:
    M 1 (P: 2), M + h² K at h = 1e-4 s 8 (P: 8), where the diagonal takes
    48 to 54.

    Attributes:
        A: the block, :class:`~nsga_jax._blocks.NodeBlockMatrix` (n × n, never
            assembled), or c_m M as a :class:`~nsga_jax._blocks.KroneckerMass`
            where the block is a scaled mass with one.
        inverse_diagonal: 1 / diag(A), shape (n,).
        preconditioner: (c_m M)⁻¹ (:class:`MassPreconditioner`), or ``None``.
        rtol: η, the relative residual each solve stops at (:func:`linear_tolerance`).
        K_norm, C_norm: Frobenius norms of the tangents A was built from (round-off floor).
        valid: False for the placeholder a run with a held operator starts with.
    """

    A: NodeBlockMatrix | KroneckerMass
    inverse_diagonal: Vector
    rtol: Scalar
    K_norm: Scalar
    C_norm: Scalar
    valid: jax.Array
    preconditioner: MassPreconditioner | None = None

    @classmethod
    def of(cls, A: NodeBlockMatrix | KroneckerMass, K_norm: Scalar, C_norm: Scalar, rtol: Scalar,
           preconditioner: MassPreconditioner | None = None) -> "KrylovOperator":
        diagonal = A.diagonal()
        return cls(A=A, inverse_diagonal=1.0 / diagonal, rtol=jnp.asarray(rtol, diagonal.dtype),
                   K_norm=K_norm, C_norm=C_norm, valid=jnp.ones((), bool), preconditioner=preconditioner)

    def forcing(self, b: Vector, bound: Scalar | None) -> Scalar:
        """The relative residual a solve with right-hand side b stops at:
        κ bound / ||b|| (so that the update's linear error is a tenth of eq.
        51's bound, module docstring), within [η, :data:`MAX_FORCING`]; η
        without a bound."""
        if bound is None:
            return self.rtol
        norm = jnp.maximum(jnp.linalg.norm(b), jnp.finfo(b.dtype).tiny)
        return jnp.clip(KAPPA * bound / norm, self.rtol, MAX_FORCING)

    def solve(self, rhs: jax.Array, bound: Scalar | None = None) -> jax.Array:
        """``A^{-1} rhs`` for rhs (n,) (or (n, m): one solve per column)."""
        if isinstance(self.A, KroneckerMass):  # c_m M, inverted exactly
            return self.A.solve(rhs) if rhs.ndim == 1 else jax.vmap(self.A.solve, in_axes=1, out_axes=1)(rhs)
        if rhs.ndim == 2:  # over rows of rhsᵀ: batched on one axis, as jax's cg needs (b and its start alike)
            return jax.vmap(lambda b: self.solve(b))(rhs.T).T
        return cg(self.A.mv, rhs, self.precondition, self.forcing(rhs, bound))

    def precondition(self, r: Vector) -> Vector:
        """(c_m M)⁻¹ r where the model has an exact M⁻¹, else diag(A)⁻¹ r."""
        if self.preconditioner is not None:
            return self.preconditioner.apply(r)
        return self.inverse_diagonal * r

    def bordered(self, r1: Vector, r2: jax.Array, G_up, G_low, active: ActiveSet, k: Scalar,
                 p: Scalar, bound: Scalar | None = None) -> tuple[Vector, jax.Array]:
        """The bordered correction (dx, dμ) by projection on the inactive
        coordinates (module docstring); the rows must be orthonormal
        :class:`~nsga_jax._assembly.NodeRows` (checked when the run is prepared)."""
        if not isinstance(G_up, NodeRows) or G_up is not G_low:
            return super().bordered(r1, r2, G_up, G_low, active, k, p, bound)
        G = NodeRows(jnp.where(active[:, None], G_up.vals, 0.0), G_up.cols, G_up.n)  # G_a, zero rows inactive

        project = projection(G)
        fixed = G.T @ (jnp.where(active, r2, 0.0) / k)
        b = project(-r1 - self.A.mv(fixed))
        z = cg(on_range(project, self.A.mv), b, on_range(project, self.precondition), self.forcing(b, bound))
        dx = fixed + project(z)
        dmu = jnp.where(active, (G @ (self.A.mv(dx) + r1)) / k, 0.0) + (p / k**2) * r2
        return dx, dmu


def projection(G: NodeRows) -> Callable[[Vector], Vector]:
    """P x = x - Gᵀ G x, the projection on the coordinates orthonormal rows G leave free."""
    return lambda x: x - G.T @ (G @ x)


def on_range(project: Callable[[Vector], Vector], apply: Callable[[Vector], Vector]) -> Callable[[Vector], Vector]:
    """P B P + (I - P) for B = ``apply``: symmetric positive definite where B
    is, and P B P on the range of P (a projected solve by conjugate gradients)."""
    return lambda x: project(apply(project(x))) + (x - project(x))


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
        A, K_norm, C_norm, preconditioner = elements()
        return KrylovOperator.of(A, K_norm, C_norm, self.rtol, preconditioner)


class KrylovHeld(KrylovFresh):
    """A's element blocks held between iterations and steps and rebuilt when
    an update made with them converges too slowly: modified Newton, as
    :class:`~nsga_jax._integrators.iteration_matrix.Held`, with an operator
    in place of LU factors (:func:`~nsga_jax._integrators.newton.newton`)."""

    is_held: ClassVar[bool] = True

    @staticmethod
    def empty_like(model: Model, dtype) -> KrylovOperator:
        """The operator a run starts with (nothing built yet): zero blocks in the model's node layout."""
        M = model.element_mass(jnp.zeros((model.n_dof,), dtype)).node_blocks()
        zero = jnp.zeros((), dtype)
        blocks = M.combine(0.0, M, 0.0)
        return KrylovOperator(A=blocks, inverse_diagonal=jnp.zeros((model.n_dof,), dtype), rtol=zero,
                              K_norm=zero, C_norm=zero, valid=jnp.zeros((), bool),
                              preconditioner=mass_preconditioner(kronecker_mass(model, dtype), 1.0))


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


def element_top_left(model: Model, ops, q: Vector, c_m, c_k):
    """``c_m M + c_k K(q)`` as node blocks, with ||K||, ||C|| = 0 (the
    round-off floor) and its preconditioner (:func:`mass_preconditioner`): a
    matrix-free sub-problem's top-left block (eqs. 47-49 with a constant
    mass, affine constraints and no damping)."""
    assert isinstance(ops.mass, ElementMass), "element blocks need a matrix-free model's operators"
    K = model.element_stiffness(q).node_blocks()
    return (ops.mass.M.combine(c_m, K, c_k), K.frobenius_norm(), jnp.zeros((), q.dtype),
            mass_preconditioner(ops.mass.kronecker, c_m))


KRYLOV_KINDS = (KrylovFresh, KrylovConstant)
"""The kinds of iteration matrices that are never assembled (a held one is a fresh one's subclass)."""
