"""The frictionless contact law as an object (nsga_jax/integrators/contact_law.py):
its active set is the residual's, its correction is the bordered Newton
correction of that active set, and it solves the linear projection it
describes."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from nsga_jax.integrators.contact_law import NormalLaw
from nsga_jax.integrators.linalg import Factorisation, solve_bordered

RNG = np.random.default_rng(3)
N, NC = 5, 4
A = jnp.asarray(np.eye(N) * 2.0 + 0.1 * RNG.standard_normal((N, N)))
G = jnp.asarray(RNG.standard_normal((NC, N)))
UNILATERAL = jnp.array([False, True, True, True])


def test_the_active_set_is_the_residuals():
    law = NormalLaw(jnp.array([True, True, True, False]), UNILATERAL, 2.0, 3.0)
    for _ in range(20):
        lam, rate = jnp.asarray(RNG.standard_normal(NC)), jnp.asarray(RNG.standard_normal(NC))
        res = law.residual(jnp.zeros(N), jnp.zeros(N), G, rate, lam, 1e-8, 1e-8)
        active, sigma, tangential = res.aux
        np.testing.assert_array_equal(active, law.active(lam, rate))
        np.testing.assert_allclose(sigma, 2.0 * lam - 3.0 * rate, rtol=1e-15)
        assert tangential is None and not law.damped
        assert not bool(active[3])  # not a candidate: never active


def test_the_correction_is_the_bordered_one_and_solves_a_linear_projection():
    """r(x, λ) = [A x - b - G^T σ_A; -k g_A; -(k²/p) λ_Ā] with g = G x - c:
    each correction is the bordered one of the residual's active set, and
    semi-smooth Newton with them reaches the root, where the active rows are
    closed and the open unilateral rows are not penetrated."""
    k = p = 1.0
    law = NormalLaw(True, UNILATERAL, k, p)
    b, c = jnp.asarray(RNG.standard_normal(N)), jnp.asarray(RNG.standard_normal(NC))
    x, lam = jnp.zeros(N), jnp.zeros(NC)
    for _ in range(30):  # semi-smooth Newton to the root
        g = G @ x - c
        res = law.residual(A @ x, b, G, g, lam, 1e-12, 1e-12)
        fac = Factorisation.of(A, jnp.zeros(()), jnp.zeros(()))
        dx, dlam = law.correction(fac, res.r[:N], res.r[N:], G, G, lam, g, None)
        expected = solve_bordered(fac, res.r[:N], res.r[N:], G, G, res.aux[0], k, p)
        np.testing.assert_array_equal(dx, expected[0])
        np.testing.assert_array_equal(dlam, expected[1])
        x, lam = x + dx, lam + dlam
    g = G @ x - c
    final = law.residual(A @ x, b, G, g, lam, 1e-12, 1e-12)
    assert float(jnp.linalg.norm(final.r)) < 1e-10
    active = final.aux[0]
    assert bool(jnp.all(jnp.abs(jnp.where(active, g, 0.0)) < 1e-10))  # active rows closed
    assert bool(jnp.all(jnp.where(UNILATERAL & ~active, g, 0.0) >= -1e-10))  # open rows not penetrated
