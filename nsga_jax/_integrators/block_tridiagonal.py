"""Block-tridiagonal solves by block elimination: O(p s³) operations for p
diagonal blocks of size s, in one ``lax.scan`` down the blocks and one back.

The system, with blocks D_i on the diagonal, L_i below (row i + 1, column i)
and U_i above (row i, column i + 1),

    L_{i-1} x_{i-1} + D_i x_i + U_i x_{i+1} = b_i,

is eliminated block by block (the block Thomas algorithm): with
W_{-1} = 0, y_{-1} = 0,

    S_i = D_i - L_{i-1} W_{i-1},   [W_i | y_i] = S_i⁻¹ [U_i | b_i - L_{i-1} y_{i-1}],

then x_{p-1} = y_{p-1} and x_i = y_i - W_i x_{i+1} back up. Each step is a
few products of s × s blocks, written as elementwise terms that XLA fuses
(:func:`_mm`), and one Gauss–Jordan elimination of the augmented block
[S_i | U_i | b_i - L_{i-1} y_{i-1}] (:func:`gauss_jordan`). On a CPU the
step's cost is the number of small kernels it runs, not its arithmetic:
eliminating the augmented block, one row update a pivot, solved 50 blocks
of 6 × 6 in 64 µs against 139 µs for a Gauss–Jordan inverse of S_i followed
by the two products, 122 against 225 µs for 100 blocks (0.52–0.70 of the
time in batches of 64); ``jnp.matmul`` with ``jnp.linalg.inv`` (a library
call a step) took 1.2–1.5× the inverse's time.

Measured and not kept (``experiments/benchmarks/bench_structured.py``,
docs/performance.md): cyclic reduction (eliminating every other block,
⌈log₂ p⌉ stages of batched products) was 1.25× faster than the inverse's
scan, but its stages are unrolled and one solve compiled in 2.7–4.5 s
against 0.5–0.75 s; eliminating from both ends at once (two half-length
sweeps batched together, ``bench_block_elimination.py``) was 1.2–1.3×
faster alone, slower in batches, and compiled twice as long; one
elementwise update a pivot was slower alone.

Nothing pivots across blocks: the Schur complements S_i must be
non-singular, which holds for matrices whose symmetric part is positive
definite (the bordered iteration matrices of
:mod:`~nsga_jax._integrators.structured`) and for block-diagonally dominant
ones.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def _mm(a: jax.Array, b: jax.Array) -> jax.Array:
    """Products of small blocks, a (..., s, s) @ b (..., s, s), as s
    elementwise terms that XLA fuses into one loop (module docstring)."""
    return sum(a[..., :, k, None] * b[..., None, k, :] for k in range(a.shape[-1]))  # type: ignore[return-value]


def _mv(a: jax.Array, x: jax.Array) -> jax.Array:
    """Batched products a (..., s, s) @ x (..., s), as :func:`_mm`."""
    return sum(a[..., :, k] * x[..., k, None] for k in range(a.shape[-1]))  # type: ignore[return-value]


def dense_of(diag: jax.Array, lower: jax.Array, upper: jax.Array) -> jax.Array:
    """The dense matrix (p s, p s) of the blocks ``diag`` (p, s, s), ``lower``
    and ``upper`` (p - 1, s, s)."""
    p, s = diag.shape[0], diag.shape[1]
    out = jnp.zeros((p, s, p, s), diag.dtype)
    i = jnp.arange(p)
    out = out.at[i, :, i, :].set(diag)
    if p > 1:
        out = out.at[i[1:], :, i[:-1], :].set(lower).at[i[:-1], :, i[1:], :].set(upper)
    return out.reshape(p * s, p * s)


def gauss_jordan(augmented: jax.Array) -> jax.Array:
    """S⁻¹ B from the augmented block [S | B], shape (s, s + c) -> (s, c), by
    Gauss–Jordan elimination without pivoting: one row update a pivot, each
    a fused loop over the block (module docstring). Its pivots are those of
    Gaussian elimination: non-zero for an S whose symmetric part is
    positive definite."""
    s = augmented.shape[0]
    for k in range(s):
        row = augmented[k] / augmented[k, k]
        augmented = (augmented - augmented[:, k:k + 1] * row[None, :]).at[k].set(row)
    return augmented[:, s:]


def solve_block_tridiagonal(diag: jax.Array, lower: jax.Array, upper: jax.Array, rhs: jax.Array) -> jax.Array:
    """x of the block-tridiagonal system (module docstring).

    Args:
        diag: diagonal blocks D_i, shape (p, s, s).
        lower: blocks L_i at (i + 1, i), shape (p - 1, s, s).
        upper: blocks U_i at (i, i + 1), shape (p - 1, s, s).
        rhs: b, shape (p, s).

    Returns:
        x, shape (p, s).
    """
    s = diag.shape[-1]
    zero = jnp.zeros((1, s, s), diag.dtype)

    def down(carry, blocks):
        W, y = carry  # S_{i-1}⁻¹ U_{i-1}, S_{i-1}⁻¹ (b_{i-1} - ...)
        D, L, U, b = blocks  # L_{i-1} (zero for the first), U_i (zero for the last)
        eliminated = gauss_jordan(jnp.concatenate([D - _mm(L, W), U, (b - _mv(L, y))[:, None]], axis=1))
        W, y = eliminated[:, :s], eliminated[:, s]
        return (W, y), (W, y)

    start = (jnp.zeros((s, s), diag.dtype), jnp.zeros((s,), rhs.dtype))
    _, (W, y) = jax.lax.scan(down, start, (diag, jnp.concatenate([zero, lower]), jnp.concatenate([upper, zero]), rhs))

    def up(x_next, wy):
        x = wy[1] - _mv(wy[0], x_next)
        return x, x

    _, x = jax.lax.scan(up, jnp.zeros((s,), rhs.dtype), (W, y), reverse=True)
    return x


__all__ = ["dense_of", "gauss_jordan", "solve_block_tridiagonal"]
