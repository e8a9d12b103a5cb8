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

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl

from .._custom_types import ActiveSet, Matrix, Scalar, Vector

Solve = Callable[[jax.Array], jax.Array]
"""``X -> A^{-1} X`` for X of shape (n,) or (n, m)."""


class Tridiagonal(eqx.Module):
    """A constant tridiagonal matrix (the iteration matrix of a chain with
    half-bandwidth 1), kept as its diagonals and solved by LAPACK's tridiagonal
    elimination at every use: O(n) work and memory per solve, where a product
    with the dense inverse is O(n²). For the 201-node bar, one solve costs about
    the same as the dense product (6.2 against 6.7 µs, call overhead
    dominating), but a batch of 64 members' solves 360 against 570 µs: the
    batch no longer streams 64 dense inverses through memory.

    Attributes:
        band: :func:`band_matrix` of the matrix with b = 1, shape (3, n):
            sub-, main and super-diagonal.
    """

    band: jax.Array

    def solve(self, rhs: jax.Array) -> jax.Array:
        """A^{-1} rhs for rhs of shape (n,) or (n, m)."""
        x = rhs if rhs.ndim == 2 else rhs[:, None]
        y = jax.lax.linalg.tridiagonal_solve(self.band[0], self.band[1], self.band[2], x)
        return y if rhs.ndim == 2 else y[:, 0]


def inverse_solve(inverse: "jax.Array | Tridiagonal") -> Solve:
    """Solve with a constant matrix factorised once: its dense inverse, or
    its diagonals (:class:`Tridiagonal`)."""
    if isinstance(inverse, Tridiagonal):
        return inverse.solve
    return lambda rhs: inverse @ rhs


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
    return sum(band[b + k] * padded[b + k:b + k + n] for k in range(-b, b + 1))


def dense_solve(matrix: jax.Array) -> Solve:
    """Solve with a fresh LU factorisation of ``matrix``."""
    return lambda rhs: jnp.linalg.solve(matrix, rhs)


class Factorisation(eqx.Module):
    """The LU factors of an iteration matrix's top-left block A, kept so that
    later Newton iterations (and steps) can solve with it again.

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
        lu, pivots = jsl.lu_factor(matrix)
        return cls(lu, pivots, K_norm, C_norm, jnp.ones((), bool))

    @classmethod
    def empty(cls, n: int, dtype) -> "Factorisation":
        zero = jnp.zeros((), dtype)
        return cls(jnp.zeros((n, n), dtype), jnp.zeros((n,), jnp.int32), zero, zero, jnp.zeros((), bool))

    def solve(self, rhs: jax.Array) -> jax.Array:
        """``A^{-1} rhs`` for rhs of shape (n,) or (n, m)."""
        return jsl.lu_solve((self.lu, self.pivots), rhs)


REDUNDANCY_SHIFT = 1e-12
"""Relative diagonal shift of a Delassus block: redundant active constraints
(four coplanar contacts on a rigid body) make it singular, and the shift
keeps the solve finite; it changes a regular solve by about 1e-12 relative,
which the Newton iteration corrects. (Multipliers of redundant constraints
stay non-unique: which ones carry the impulse depends on the active set.)"""


def masked_solve(D: jax.Array, rhs: jax.Array, active: ActiveSet) -> jax.Array:
    """Solve ``D[a, a] x[a] = rhs[a]``; x is zero on inactive rows."""
    if D.shape[0] == 1:  # one constraint: a division (an LU call costs more here)
        return jnp.where(active, rhs / jnp.where(active, D[0], 1.0), 0.0)
    both = active[:, None] & active[None, :]
    eye = jnp.eye(D.shape[0], dtype=D.dtype)
    shift = REDUNDANCY_SHIFT * jnp.max(jnp.abs(jnp.diagonal(D)))
    Dm = jnp.where(both, D + shift * eye, eye)
    return jnp.where(active, jnp.linalg.solve(Dm, jnp.where(active, rhs, 0.0)), 0.0)


def solve_bordered(
    solve: Solve,
    r1: Vector,
    r2: jax.Array,
    G_up: jax.Array,
    G_low: jax.Array,
    active: ActiveSet,
    k: Scalar,
    p: Scalar,
    A_inv_Gt: jax.Array | None = None,
) -> tuple[Vector, jax.Array]:
    """Newton correction (dx, dmu) of a bordered system (see module docstring).

    Args:
        solve: applies A^{-1}.
        r1: coordinate residual, shape (n,).
        r2: constraint residual, shape (m,).
        G_up, G_low: constraint gradient blocks, shape (m, n).
        active: active-set mask, shape (m,).
        k, p: multiplier scaling and penalty.
        A_inv_Gt: A^{-1} G_up^T, shape (n, m), when it is precomputed.
    """
    if A_inv_Gt is None:
        sol = solve(jnp.concatenate([r1[:, None], G_up.T], axis=1))
        y, A_inv_Gt = sol[:, 0], sol[:, 1:]
    else:
        y = solve(r1)
    D = G_low @ A_inv_Gt
    dmu_red = masked_solve(D, r2 / k**2 + (G_low @ y) / k, active)
    dx = -y + k * (A_inv_Gt @ dmu_red)
    dmu = dmu_red + (p / k**2) * r2
    return dx, dmu
