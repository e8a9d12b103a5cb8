"""The Schur-complement solve of the bordered iteration matrices."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from nsga_jax._integrators.iteration_matrix import ConstantInverse
from nsga_jax._integrators.linalg import Factorisation, solve_bordered


def full_matrix(A, Gu, Gl, a, k, p):
    m = len(a)
    Da = np.diag(a.astype(float))
    top = np.hstack([A + p * Gu.T @ Da @ Gl, -k * Gu.T @ Da])
    bottom = np.hstack([-k * Da @ Gl, -(k**2 / p) * np.diag(1.0 - a)])
    return np.vstack([top, bottom]) if m else top


@pytest.mark.parametrize("mask", [[1, 1, 1], [1, 0, 1], [0, 0, 0], [0, 1, 0]])
@pytest.mark.parametrize("symmetric", [True, False])
def test_schur_solve_equals_full_bordered_solve(mask, symmetric):
    rng = np.random.default_rng(1)
    n, m = 7, 3
    B = rng.normal(size=(n, n))
    A = B @ B.T + n * np.eye(n)
    Gu = rng.normal(size=(m, n))
    Gl = Gu if symmetric else Gu + 0.3 * rng.normal(size=(m, n))
    a = np.array(mask, bool)
    k, p = 2.5, 1.7
    r1, r2 = rng.normal(size=n), rng.normal(size=m)
    expected = np.linalg.solve(full_matrix(A, Gu, Gl, a, k, p), -np.concatenate([r1, r2]))
    zero = jnp.zeros(())
    lu = Factorisation.of(jnp.asarray(A), zero, zero)
    # LU factors; a constant inverse without, and with its precomputed A^{-1} Gu^T
    for matrix in (lu, ConstantInverse.of(jnp.asarray(A), None, zero, zero),
                   ConstantInverse.of(jnp.asarray(A), jnp.asarray(Gu), zero, zero)):
        dx, dmu = solve_bordered(matrix, jnp.asarray(r1), jnp.asarray(r2), jnp.asarray(Gu), jnp.asarray(Gl),
                                 jnp.asarray(a), k, p)
        np.testing.assert_allclose(np.concatenate([dx, dmu]), expected, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("b", [0, 1, 2])
def test_band_product_equals_the_dense_product(b):
    from nsga_jax._integrators.linalg import band_matrix, band_product

    rng = np.random.default_rng(b)
    n = 9
    A = rng.normal(size=(n, n))
    A[np.abs(np.subtract.outer(np.arange(n), np.arange(n))) > b] = 0.0
    x = rng.normal(size=n)
    band = band_matrix(jnp.asarray(A), b)
    assert band.shape == (2 * b + 1, n)
    np.testing.assert_allclose(band_product(band, jnp.asarray(x)), A @ x, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("n", [1, 2, 11, 201])
def test_tridiagonal_solve_equals_the_dense_solve(n):
    from nsga_jax._integrators.linalg import Tridiagonal, band_matrix

    rng = np.random.default_rng(n)
    A = rng.normal(size=(n, n)) + 4.0 * np.eye(n)  # non-symmetric, diagonally dominant
    A[np.abs(np.subtract.outer(np.arange(n), np.arange(n))) > 1] = 0.0
    solve = jax.jit(lambda b, rhs: Tridiagonal.of(b).solve(rhs))
    band = band_matrix(jnp.asarray(A), 1)
    x, X = rng.normal(size=n), rng.normal(size=(n, 2))
    np.testing.assert_allclose(solve(band, jnp.asarray(x)), np.linalg.solve(A, x), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(solve(band, jnp.asarray(X)), np.linalg.solve(A, X), rtol=1e-12, atol=1e-13)


def test_tridiagonal_solve_of_a_stiff_chain_matches_lapack_accuracy():
    """c M + K of a free chain (consistent mass, unit springs) with cond ~ 4e6: the
    block elimination's residual is within a small factor of LAPACK's."""
    from nsga_jax._integrators.linalg import Tridiagonal, band_matrix

    n, c = 1000, 1e-6
    off = (c / 6 - 1.0) * np.ones(n - 1)
    diag = (2.0 + 4 * c / 6) * np.ones(n)
    diag[[0, -1]] = 1.0 + 2 * c / 6
    A = np.diag(diag) + np.diag(off, 1) + np.diag(off, -1)
    x = np.random.default_rng(0).normal(size=n)
    ours = np.asarray(jax.jit(lambda b, rhs: Tridiagonal.of(b).solve(rhs))(band_matrix(jnp.asarray(A), 1),
                                                                            jnp.asarray(x)))
    lapack = np.linalg.solve(A, x)
    assert np.abs(A @ ours - x).max() <= 10 * max(np.abs(A @ lapack - x).max(), 1e-15)
    np.testing.assert_allclose(ours, lapack, rtol=0, atol=1e-9 * np.abs(lapack).max())


def test_the_bar_solves_its_constant_matrices_by_tridiagonal_elimination():
    import equinox as eqx

    from nsga_jax._integrators.iteration_matrix import ConstantTridiagonal
    from nsga_jax.scenes import load_scene

    scene = load_scene("impacting_bar")
    ops = eqx.filter_jit(lambda h: scene.scheme().prepare(scene.model, h, 0.0))(1e-3)
    for matrix in (ops.smooth, ops.position, ops.velocity):
        assert isinstance(matrix, ConstantTridiagonal) and matrix.elimination.n == scene.model.n_dof
    G = np.asarray(ops.constraints.G)
    A = np.asarray(ops.mass.M) + 1e-6 * np.asarray(ops.force.K)  # DS's position matrix M + h² K
    np.testing.assert_allclose(ops.position.inverse_Gt, np.linalg.solve(A, G.T), rtol=1e-10,
                               atol=1e-12 * np.abs(np.linalg.solve(A, G.T)).max())


def lu_operand_shapes(jaxpr) -> list[tuple[int, ...]]:
    """Shapes of the matrices handed to LU factorisations anywhere in ``jaxpr``
    (sub-jaxprs of loops, conditionals and custom rules included)."""
    shapes = []
    for eqn in jaxpr.eqns:
        if eqn.primitive.name == "lu":
            shapes.append(eqn.invars[0].aval.shape)
        for value in eqn.params.values():
            for sub in value if isinstance(value, (tuple, list)) else (value,):
                inner = getattr(sub, "jaxpr", sub)
                if hasattr(inner, "eqns"):
                    shapes += lu_operand_shapes(inner)
    return shapes


@pytest.mark.parametrize("n, chunked", [(27, True), (4, False)])
def test_bounded_lapack_batches_chunk_a_vmapped_batch_with_the_same_results(n, chunked):
    """Traced under bounded_lapack_batches, a vmap over the factorisations and
    solves hands each LU call at most LAPACK_WORK_PER_CALL of work (larger
    batched calls deadlock jaxlib 0.10 on several CPU devices): 27 × 27
    matrices one per call, small ones still in one batched call; the results
    are the batched ones."""
    from nsga_jax._compat import LAPACK_WORK_PER_CALL, bounded_lapack_batches
    from nsga_jax._integrators.linalg import Tridiagonal, band_matrix, dense_solve, masked_solve

    def work(shape):
        return np.prod(shape[:-2], dtype=int) * shape[-1] ** 3

    rng = np.random.default_rng(3)
    B, m = 6, 3
    A = rng.normal(size=(B, n, n)) + n * np.eye(n)
    rhs = rng.normal(size=(B, n))
    D = rng.normal(size=(B, m, m)) + m * np.eye(m)
    active = np.array([True, False, True])
    tri = np.where(np.abs(np.subtract.outer(np.arange(n), np.arange(n))) > 1, 0.0, A)

    def solves(A, rhs, D, tri):
        return (Factorisation.of(A, 0.0, 0.0).solve(rhs), dense_solve(A)(rhs), masked_solve(D, rhs[:m], active),
                Tridiagonal.of(band_matrix(tri, 1)).solve(rhs))

    args = tuple(jnp.asarray(x) for x in (A, rhs, D, tri))
    # (a new function object per trace: JAX reuses a function's earlier trace)
    whole = lu_operand_shapes(jax.make_jaxpr(jax.vmap(solves))(*args).jaxpr)
    with bounded_lapack_batches():
        bounded_jaxpr = jax.make_jaxpr(jax.vmap(solves))(*args)
        bounded = jax.jit(jax.vmap(solves))(*args)
    shapes = lu_operand_shapes(bounded_jaxpr.jaxpr)
    assert len(shapes) == len(whole)
    assert all(work(s) <= LAPACK_WORK_PER_CALL for s in shapes), shapes
    assert bool(max(map(work, whole)) > LAPACK_WORK_PER_CALL) is chunked
    if chunked:
        assert (B, n, n) in whole and (1, n, n) in shapes  # one matrix per call
    else:
        assert shapes == whole
    for x, y in zip(bounded, jax.jit(jax.vmap(solves))(*args)):
        np.testing.assert_allclose(x, y, rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(bounded[0], np.linalg.solve(A, rhs[..., None])[..., 0], rtol=1e-12)


def test_redundancy_shift_survives_float32_and_leaves_float64_unchanged(monkeypatch):
    """The Delassus shift never falls below the precision's round-off: 1e-12
    relative is lost in float32 (d + 1e-12 d == d), and a block with
    redundant rows (two contacts sharing a row, as a box's corners on an
    incline share their tangent) was exactly singular there, NaN in the
    compiled solve. float64 keeps the constant 1e-12 itself."""
    from nsga_jax._integrators import linalg
    from nsga_jax._integrators.linalg import REDUNDANCY_SHIFT, masked_solve, redundancy_shift

    assert redundancy_shift(jnp.float64) == REDUNDANCY_SHIFT
    shift32 = redundancy_shift(jnp.float32)
    assert np.float32(1.0) + np.float32(shift32) > np.float32(1.0) and shift32 < 1e-4
    G = np.array([[1.0, 2.0, 0.0], [1.0, 2.0, 0.0], [0.0, 1.0, 1.0]])  # rows 0 and 1 redundant
    D = jnp.asarray(G @ G.T, jnp.float32)
    rhs = jnp.asarray([5.0, 5.0, 2.0], jnp.float32)  # consistent: the rows agree
    active = jnp.ones(3, bool)
    x = jax.jit(masked_solve)(D, rhs, active)
    assert np.all(np.isfinite(x))
    np.testing.assert_allclose(D @ x, rhs, rtol=1e-3)
    monkeypatch.setattr(linalg, "REDUNDANCY_SHIFT_EPS", 0.0)  # the float64 constant alone: lost in float32
    # (a new function object: jit would reuse the trace above)
    assert not np.all(np.isfinite(jax.jit(lambda *a: masked_solve(*a))(D, rhs, active)))
