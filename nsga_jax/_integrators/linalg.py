"""Linear algebra of the iteration matrices (paper eqs. 47-49).

Each sub-problem's iteration matrix is *bordered*: a top-left block on the
coordinates and a constraint block, with an active-set mask ``a``:

    [ A + p Gu^T diag(a) Gl    -k Gu^T diag(a)      ] [dx ]     [r1]
    [ -k diag(a) Gl            -(k^2/p) diag(1-a)   ] [dmu] = - [r2]

(smooth motion: Gu = g_q^B, Gl = g_q^B + (hβ/γ) G^s, all rows active;
position: Gu = Gl = g_q, a = A; velocity: Gu = Gl = g_q, a = B).

It is solved by a Schur complement on the (small) active constraint block,
with A the top-left block *without* its penalty term p Gu^T a Gl. Eliminating
the active rows ``Gl dx = r2/k`` shows that the penalty term only shifts the
multiplier correction by ``(p/k^2) r2``, so the iterates are exactly those of
the full matrix (the solution never depends on k and p, only the conditioning
does). This lets a linear model keep one constant factorisation of A for every
active set. A must be non-singular, which holds when M is positive definite.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Callable
from typing import cast

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl

from .._compat import lapack_batches_bounded
from .._custom_types import ActiveSet, Matrix, Scalar, Vector

Solve = Callable[[jax.Array], jax.Array]
"""``X -> A^{-1} X`` for X of shape (n,) or (n, m)."""

@lapack_batches_bounded
def lu_factor(matrix: Matrix) -> tuple[Matrix, jax.Array]:
    """``jax.scipy.linalg.lu_factor``: the LU factors (n, n) and pivots (n,)."""
    return jsl.lu_factor(matrix)


@lapack_batches_bounded
def lu_solve(lu: Matrix, pivots: jax.Array, rhs: jax.Array) -> jax.Array:
    """``jax.scipy.linalg.lu_solve``: A^{-1} rhs from A's LU factors."""
    return jsl.lu_solve((lu, pivots), rhs)


@lapack_batches_bounded
def linear_solve(matrix: Matrix, rhs: jax.Array) -> jax.Array:
    """``jnp.linalg.solve``: matrix^{-1} rhs."""
    return jnp.linalg.solve(matrix, rhs)


@lapack_batches_bounded
def inverse(matrix: Matrix) -> Matrix:
    """``jnp.linalg.inv`` of a matrix or a stack of them, shape (..., n, n)."""
    return jnp.linalg.inv(matrix)


class Tridiagonal(eqx.Module):
    """A constant tridiagonal matrix (the iteration matrix of a chain with
    half-bandwidth 1), factorised once by block elimination so that every
    solve is three small dense products and no library call.

    The n unknowns (padded with decoupled identity rows to p (s + 1) - 1,
    s ≈ √n) are split into p interior blocks of s consecutive unknowns and
    the p - 1 single *separator* unknowns between them. Eliminating the
    blocks leaves the separators' Schur complement Σ = A_SS - A_SI A_II^{-1} A_IS,
    itself tridiagonal. With the blocks' inverses and Σ^{-1} precomputed, a
    solve is y = A_II^{-1} b_I (p products of s × s), x_S = Σ^{-1} (b_S - A_SI y),
    x_I = y - A_II^{-1} A_IS x_S (two columns of each block inverse): about
    p s² + p² ≈ 2 n^{1.5} multiply-adds, where the dense inverse takes n².
    For the 201-node bar one solve costs about a third of LAPACK's
    tridiagonal elimination (``experiments/benchmarks/bench_tridiagonal.py``).

    Block elimination does not pivot: the diagonal blocks and Σ must be
    non-singular, which holds for the symmetric positive definite (and the
    diagonally dominant) matrices M + c K of a chain with positive mass.

    Attributes:
        blocks_inv: inverses of the interior blocks, shape (p, s, s).
        to_separator: couplings of separator k to the last unknown of block k
            and to the first of block k + 1, shape (2, p - 1).
        from_separator: couplings of block k's last row and of block k + 1's
            first row to separator k, shape (2, p - 1).
        schur_inv: Σ^{-1}, shape (p - 1, p - 1).
        n: the matrix size (static).
    """

    blocks_inv: jax.Array
    to_separator: jax.Array
    from_separator: jax.Array
    schur_inv: jax.Array
    n: int = eqx.field(static=True)

    @classmethod
    def of(cls, band: jax.Array) -> "Tridiagonal":
        """Factorise the matrix with diagonals ``band`` (:func:`band_matrix`, b = 1), shape (3, n)."""
        n = band.shape[-1]
        s = math.isqrt(max(n, 1) - 1) + 1  # ceil(sqrt(n))
        p = max(2, -(-(n + 1) // (s + 1)))
        pad = p * (s + 1) - n
        lower, diag, upper = (jnp.pad(band[i], (0, pad), constant_values=float(i == 1)).reshape(p, s + 1)
                              for i in range(3))
        blocks = (diag[:, :s, None] * jnp.eye(s, dtype=band.dtype)
                  + lower[:, :s, None] * jnp.eye(s, k=-1, dtype=band.dtype)
                  + upper[:, :s, None] * jnp.eye(s, k=1, dtype=band.dtype))
        inv = inverse(blocks)
        to_left, to_right = lower[:-1, s], upper[:-1, s]  # separator k -> block k's last, block k+1's first
        last_row, first_row = upper[:-1, s - 1], lower[1:, 0]  # block k's last, block k+1's first -> separator k
        schur = (jnp.diag(diag[:-1, s] - to_left * inv[:-1, s - 1, s - 1] * last_row
                          - to_right * inv[1:, 0, 0] * first_row)
                 + jnp.diag(-to_right[:-1] * inv[1:-1, 0, s - 1] * last_row[1:], 1)
                 + jnp.diag(-to_left[1:] * inv[1:-1, s - 1, 0] * first_row[:-1], -1))
        return cls(inv, jnp.stack([to_left, to_right]), jnp.stack([last_row, first_row]),
                   inverse(schur), n)

    def solve(self, rhs: jax.Array) -> jax.Array:
        """A^{-1} rhs for rhs of shape (n,) or (n, m)."""
        p, s = self.blocks_inv.shape[0], self.blocks_inv.shape[-1]
        rest = rhs.shape[1:]

        def per_row(c):  # a vector over blocks or separators, broadcast against the right-hand sides
            return c.reshape(-1, *([1] * len(rest)))

        padded = jnp.pad(rhs, [(0, p * (s + 1) - self.n)] + [(0, 0)] * len(rest)).reshape(p, s + 1, *rest)
        y = jnp.einsum("kij,kj...->ki...", self.blocks_inv, padded[:, :s])
        to_left, to_right = self.to_separator
        x_sep = self.schur_inv @ (padded[:-1, s] - per_row(to_left) * y[:-1, s - 1] - per_row(to_right) * y[1:, 0])
        last_row, first_row = self.from_separator
        zero = jnp.zeros((1, *rest), rhs.dtype)
        into_last = jnp.concatenate([per_row(last_row) * x_sep, zero])  # A_IS x_S on each block's last row
        into_first = jnp.concatenate([zero, per_row(first_row) * x_sep])  # ... and on its first row
        cols = (slice(None), slice(None)) + (None,) * len(rest)
        x = (y - self.blocks_inv[:, :, s - 1][cols] * into_last[:, None]
             - self.blocks_inv[:, :, 0][cols] * into_first[:, None])
        out = jnp.concatenate([x, jnp.concatenate([x_sep, zero])[:, None]], axis=1)
        return out.reshape(p * (s + 1), *rest)[: self.n]


def band_matrix(matrix: Matrix, b: int) -> jax.Array:
    """The 2b + 1 diagonals of a banded matrix, shape (2b + 1, n):
    ``band[b + k, i] = matrix[i, i + k]`` (zero where i + k is outside)."""
    n = matrix.shape[0]
    rows = [jnp.pad(jnp.diagonal(matrix, k), (max(-k, 0), max(k, 0))) for k in range(-b, b + 1)]
    return jnp.stack(rows) if n else jnp.zeros((2 * b + 1, 0), matrix.dtype)


def band_product(band: jax.Array, x: Vector) -> Vector:
    """``matrix @ x`` from :func:`band_matrix`'s diagonals: 2b + 1 shifted
    elementwise products, O(b n) and one fused loop, where the dense product
    is O(n²) and the element-by-element one a gather and a scatter."""
    b = (band.shape[0] - 1) // 2
    n = x.shape[0]
    padded = jnp.pad(x, (b, b))
    # a sum of 2b + 1 >= 1 arrays: never the empty sum's 0
    return cast(jax.Array, sum(band[b + k] * padded[b + k:b + k + n] for k in range(-b, b + 1)))


def dense_solve(matrix: jax.Array) -> Solve:
    """Solve with a fresh LU factorisation of ``matrix``."""
    return lambda rhs: linear_solve(matrix, rhs)


class AbstractFactorisation(eqx.Module):
    """An iteration matrix's top-left block A (eqs. 47-49) in a form ready to
    solve with, and the norms of the tangents it was built from.

    Attributes:
        K_norm, C_norm: Frobenius norms of the stiffness and damping matrices
            A was built from (the round-off floor of the residual uses them).
    """

    K_norm: eqx.AbstractVar[Scalar]
    C_norm: eqx.AbstractVar[Scalar]

    @abc.abstractmethod
    def solve(self, rhs: jax.Array, bound: Scalar | None = None) -> jax.Array:
        """``A^{-1} rhs`` for rhs of shape (n,) or (n, m). ``bound``: eq. 51's
        bound at the iterate, which an iterative solve may leave a fraction
        of as its residual (a factorisation solves exactly and ignores it)."""

    def solve_with_constraints(self, rhs: Vector, G: jax.Array) -> tuple[Vector, jax.Array]:
        """``(A^{-1} rhs, A^{-1} G^T)`` for rhs (n,) and G (m, n): one solve
        with m + 1 right-hand sides (a constant matrix may have A^{-1} G^T
        precomputed)."""
        sol = self.solve(jnp.concatenate([rhs[:, None], G.T], axis=1))
        return sol[:, 0], sol[:, 1:]

    def bordered(self, r1: Vector, r2: jax.Array, G_up: jax.Array, G_low: jax.Array, active: ActiveSet,
                 k: Scalar, p: Scalar, bound: Scalar | None = None) -> tuple[Vector, jax.Array]:
        """The Newton correction (dx, dmu) of the bordered system with this
        top-left block (:func:`solve_bordered`; ``bound`` as in :meth:`solve`)."""
        return solve_bordered(self, r1, r2, G_up, G_low, active, k, p)


class Factorisation(AbstractFactorisation):
    """The LU factors of an iteration matrix's top-left block A, for the
    Newton corrections at one iterate (and, held, at later iterations and steps).

    Attributes:
        lu, pivots: ``jax.scipy.linalg.lu_factor(A)``, shapes (n, n) and (n,).
        K_norm, C_norm: Frobenius norms of the tangents A was built from (the
            round-off floor of the residual uses them).
        valid: False for the placeholder a run starts with (nothing factored yet).
    """

    lu: Matrix
    pivots: jax.Array
    K_norm: Scalar
    C_norm: Scalar
    valid: jax.Array

    @classmethod
    def of(cls, matrix: Matrix, K_norm: Scalar, C_norm: Scalar) -> "Factorisation":
        lu, pivots = lu_factor(matrix)
        return cls(lu=lu, pivots=pivots, K_norm=K_norm, C_norm=C_norm, valid=jnp.ones((), bool))

    @classmethod
    def empty(cls, n: int, dtype) -> "Factorisation":
        zero = jnp.zeros((), dtype)
        return cls(lu=jnp.zeros((n, n), dtype), pivots=jnp.zeros((n,), jnp.int32), K_norm=zero, C_norm=zero,
                   valid=jnp.zeros((), bool))

    def solve(self, rhs: jax.Array, bound: Scalar | None = None) -> jax.Array:
        """``A^{-1} rhs`` for rhs of shape (n,) or (n, m)."""
        return lu_solve(self.lu, self.pivots, rhs)


REDUNDANCY_SHIFT = 1e-12
"""Relative diagonal shift of a Delassus block: redundant active constraints
(four coplanar contacts on a rigid body) make it singular, and the shift
keeps the solve finite; it changes a regular solve by about 1e-12 relative,
which the Newton iteration corrects. (Multipliers of redundant constraints
stay non-unique: which ones carry the impulse depends on the active set.)
The shift in use is :func:`redundancy_shift`, never below the precision's
round-off."""

REDUNDANCY_SHIFT_EPS = 64.0
"""The least relative shift in units of the precision's eps. 1e-12 is below
float32's eps (1.2e-7): there ``d + 1e-12 d`` rounds back to ``d``, the shift
is lost, and redundant rows (two corners of a box on an incline share their
tangent row) leave the block exactly singular, a zero pivot and NaN in the
compiled LU (eager LU happened to leave a round-off pivot). 64 eps (7.6e-6
in float32, the residual floors' factor) keeps the shifted pivot well above
the elimination's round-off while perturbing a regular solve no more than
float32's convergence floor; in float64 it is 1.4e-14 < 1e-12, so float64's
shift is unchanged."""


def redundancy_shift(dtype) -> float:
    """The relative diagonal shift of a Delassus block in precision ``dtype``:
    ``max(REDUNDANCY_SHIFT, REDUNDANCY_SHIFT_EPS * eps)`` (a Python number, so
    that float64's arithmetic is exactly that of the constant 1e-12)."""
    return max(REDUNDANCY_SHIFT, REDUNDANCY_SHIFT_EPS * float(jnp.finfo(dtype).eps))


MINIMUM_NORM_RTOL = 1e-10
"""Singular values below this fraction of the largest count as zero in
:func:`minimum_norm_split` (never below :data:`REDUNDANCY_SHIFT_EPS` eps)."""


def minimum_norm_split(matrix: Matrix, rhs: jax.Array, regularised: Matrix) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The minimum-norm least-squares solution of ``matrix x = rhs``, the
    null-space direction that a regularisation selects, and the norm of the
    inconsistent part of ``rhs``, by SVD ``matrix = U Σ Vᵀ``:

        x₀ = Σ_{σ_i > τ} v_i (u_iᵀ rhs) / σ_i,    n = V_0 V_0ᵀ (regularised⁻¹ rhs),
        ||matrix x₀ - rhs|| = ||U_0ᵀ rhs||,

    with τ = ``max(MINIMUM_NORM_RTOL, REDUNDANCY_SHIFT_EPS eps)`` σ_max and
    V_0, U_0 the singular vectors of the singular values <= τ. For a regular
    matrix x₀ is the solution and n ≈ 0. For a singular one x₀ has no part in
    the null space, and n is the null-space part of the solution of the
    ``regularised`` matrix (``matrix`` plus a small shift): its direction is
    that of the shift's limit, its length of the order of the inconsistent
    part divided by the shift, and the caller chooses the length to take."""
    # factors without tangent: linear in rhs (Newton's implicit JVP); the SVD's own is NaN at σ = 0
    U, sv, Vh = jax.lax.stop_gradient(jnp.linalg.svd(matrix))
    tol = max(MINIMUM_NORM_RTOL, REDUNDANCY_SHIFT_EPS * float(jnp.finfo(matrix.dtype).eps)) * sv[0]
    c = U.T @ rhs
    kept = sv > tol
    x0 = Vh.T @ jnp.where(kept, c / jnp.where(kept, sv, 1.0), 0.0)
    null = Vh.T @ jnp.where(kept, 0.0, Vh @ linear_solve(regularised, rhs))
    return x0, null, jnp.linalg.norm(jnp.where(kept, 0.0, c))


def masked_solve(D: jax.Array, rhs: jax.Array, active: ActiveSet) -> jax.Array:
    """Solve ``D[a, a] x[a] = rhs[a]``; x is zero on inactive rows."""
    if D.shape[0] == 1:  # one constraint: a division (an LU call costs more here)
        return jnp.where(active, rhs / jnp.where(active, D[0], 1.0), 0.0)
    both = active[:, None] & active[None, :]
    eye = jnp.eye(D.shape[0], dtype=D.dtype)
    shift = redundancy_shift(D.dtype) * jnp.max(jnp.abs(jnp.diagonal(D)))
    Dm = jnp.where(both, D + shift * eye, eye)
    return jnp.where(active, linear_solve(Dm, jnp.where(active, rhs, 0.0)), 0.0)


def solve_bordered(
    matrix: AbstractFactorisation,
    r1: Vector,
    r2: jax.Array,
    G_up: jax.Array,
    G_low: jax.Array,
    active: ActiveSet,
    k: Scalar,
    p: Scalar,
) -> tuple[Vector, jax.Array]:
    """Newton correction (dx, dmu) of a bordered system (see module docstring).

    Args:
        matrix: the top-left block A, ready to solve with (its A^{-1} G_up^T
            may be precomputed: :meth:`AbstractFactorisation.solve_with_constraints`).
        r1: coordinate residual, shape (n,).
        r2: constraint residual, shape (m,).
        G_up, G_low: constraint gradient blocks, shape (m, n).
        active: active-set mask, shape (m,).
        k, p: multiplier scaling and penalty.
    """
    y, A_inv_Gt = matrix.solve_with_constraints(r1, G_up)
    D = G_low @ A_inv_Gt
    dmu_red = masked_solve(D, r2 / k**2 + (G_low @ y) / k, active)
    dx = -y + k * (A_inv_Gt @ dmu_red)
    dmu = dmu_red + (p / k**2) * r2
    return dx, dmu


MULTIPLIER_RTOL = 1e-10
"""Relative cut of the pseudo-inverse in :func:`saddle_acceleration`
(:func:`~nsga_jax._integrators.model_terms.consistent_acceleration`):
eigenvalues of G M⁻¹ Gᵀ below ``rtol`` times the largest are those of
redundant rows (their round-off is about eps times the largest, far below),
never of a mechanism's regular rows (a condition number above 1e10 would be
one). The cut in use is :func:`multiplier_rtol`, never below the precision's
round-off."""


def multiplier_rtol(dtype) -> float:
    """The pseudo-inverse's relative cut in precision ``dtype``:
    ``max(MULTIPLIER_RTOL, 1e3 eps)`` (1e-10 in float64, 1.2e-4 in float32)."""
    return max(MULTIPLIER_RTOL, 1e3 * float(jnp.finfo(dtype).eps))


def saddle_acceleration(M: Matrix, f: Vector, G: Matrix, conv: jax.Array) -> tuple[Vector, jax.Array]:
    """The acceleration v̇ (n,) and multipliers λ (rows,) of M v̇ = f + Gᵀ λ
    with the rows G v̇ + conv = 0 held (M symmetric positive definite), λ
    the minimum-norm choice, (G M⁻¹ Gᵀ)⁺ (-conv - G M⁻¹ f), the pseudo-inverse
    cut at :func:`multiplier_rtol` (redundant rows share the load; zero rows
    take λ = 0): :func:`~nsga_jax._integrators.model_terms.consistent_acceleration`
    and the held contacts of :mod:`~nsga_jax._integrators.impact_instants`."""
    Minv = jnp.linalg.solve(M, jnp.concatenate([f[:, None], G.T], axis=1))
    Minv_f, Minv_Gt = Minv[:, 0], Minv[:, 1:]
    A = G @ Minv_Gt
    A = 0.5 * (A + A.T)  # symmetric up to round-off; the pseudo-inverse of a symmetric matrix
    lam = jnp.linalg.pinv(A, rtol=multiplier_rtol(A.dtype), hermitian=True) @ (-conv - G @ Minv_f)
    return Minv_f + Minv_Gt @ lam, lam
