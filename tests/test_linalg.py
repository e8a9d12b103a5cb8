"""The Schur-complement solve of the bordered iteration matrices."""

import jax.numpy as jnp
import numpy as np
import pytest

from nsga_jax.integrators.linalg import Factorisation, dense_solve, inverse_solve, solve_bordered


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
    lu = Factorisation.of(jnp.asarray(A), jnp.zeros(()), jnp.zeros(()))
    for solve, pre in ((dense_solve(jnp.asarray(A)), None), (lu.solve, None),
                       (inverse_solve(jnp.asarray(np.linalg.inv(A))), jnp.asarray(np.linalg.solve(A, Gu.T)))):
        dx, dmu = solve_bordered(solve, jnp.asarray(r1), jnp.asarray(r2), jnp.asarray(Gu), jnp.asarray(Gl),
                                 jnp.asarray(a), k, p, pre)
        np.testing.assert_allclose(np.concatenate([dx, dmu]), expected, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("b", [0, 1, 2])
def test_band_product_equals_the_dense_product(b):
    from nsga_jax.integrators.linalg import band_matrix, band_product

    rng = np.random.default_rng(b)
    n = 9
    A = rng.normal(size=(n, n))
    A[np.abs(np.subtract.outer(np.arange(n), np.arange(n))) > b] = 0.0
    x = rng.normal(size=n)
    band = band_matrix(jnp.asarray(A), b)
    assert band.shape == (2 * b + 1, n)
    np.testing.assert_allclose(band_product(band, jnp.asarray(x)), A @ x, rtol=1e-14, atol=1e-14)
