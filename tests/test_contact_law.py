"""The frictionless contact law as an object (nsga_jax/_integrators/contact_law.py):
its active set is the residual's, its correction is the bordered Newton
correction of that active set, and it solves the linear projection it
describes."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from nsga_jax._integrators.contact_law import NormalLaw, linearised_active
from nsga_jax._integrators.friction import contact_law
from nsga_jax._integrators.linalg import Factorisation, solve_bordered

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


def test_newtons_matrix_closes_the_rows_at_round_off_of_zero_only():
    """σ = k Λ - p c a round-off below zero (within 64 eps of the largest
    |σ|: a gap of +1e-18 m between boxes the smooth step moved alike) is
    closed in Newton's matrix and open in the law; σ below that (1e-12 of
    the largest) is open in both. The law's values (impulses, rows,
    active set) are the same whichever derivative is taken, so the residual
    and the solution do not change."""
    aug = jnp.array([1.0, -1e-15, -1e-12, 0.0, -1e-15])
    candidates = jnp.array([True, True, True, True, False])
    unilateral = jnp.ones(5, bool)
    np.testing.assert_array_equal(linearised_active(aug, candidates, unilateral), [True, True, False, True, False])
    law = NormalLaw(candidates, unilateral, 1.0, 1.0)
    np.testing.assert_array_equal(law.active(jnp.zeros(5), -aug), [True, False, False, True, False])
    # a joint's large reaction (a bilateral row) does not widen the contacts' band: a contact open by
    # 1e-10 of the contacts' largest |σ| stays open in the matrix
    joint = jnp.array([1e6, -1e-15, -1.0, -1e-10, -1e-15])
    np.testing.assert_array_equal(linearised_active(joint, candidates, unilateral.at[0].set(False)),
                                  [True, True, False, False, False])
    # NormalLaw's correction is the bordered one of the widened set
    k = p = 1.0
    lam, rate = jnp.zeros(NC), jnp.array([-1.0, 1e-15, 1.0, 0.0])
    normal = NormalLaw(True, UNILATERAL, k, p)
    res = normal.residual(jnp.zeros(N), jnp.ones(N), G, rate, lam, 1e-12, 1e-12)
    fac = Factorisation.of(A, jnp.zeros(()), jnp.zeros(()))
    widened = linearised_active(k * lam - p * rate, True, UNILATERAL)
    np.testing.assert_array_equal(widened, [True, True, False, True])
    assert not bool(res.aux[0][1])  # open in the law
    got = normal.correction(fac, res.r[:N], res.r[N:], G, G, lam, rate, None)
    expected = solve_bordered(fac, res.r[:N], res.r[N:], G, G, widened, k, p)
    np.testing.assert_array_equal(got[0], expected[0])
    np.testing.assert_array_equal(got[1], expected[1])
    # with friction: two contacts, d = 2; the second at σ_N = -1e-15
    lam, rate = jnp.array([0.5, 0.0, 0.1, 0.0, 0.2, 0.1]), jnp.array([0.0, 1e-15, 0.0, 0.3, 0.0, 0.0])
    args = (jnp.ones(2, bool), jnp.ones(2, bool), jnp.array([0.5, 0.5]), (0, 1), 2, 1.0, 1.0, jnp.ones(2))
    plain, widened = contact_law(lam, rate, *args), contact_law(lam, rate, *args, linearised=True)
    for a, b in zip(plain, widened):
        np.testing.assert_array_equal(a, b)
    assert not bool(plain.active[1])
    d_plain = jax.jacfwd(lambda x: contact_law(x, rate, *args).impulse)(lam)
    d_widened = jax.jacfwd(lambda x: contact_law(x, rate, *args, linearised=True).impulse)(lam)
    assert float(d_plain[1, 1]) == 0.0 and float(d_widened[1, 1]) == 1.0  # dP_N/dΛ_N of the touching contact
    np.testing.assert_array_equal(d_plain[0], d_widened[0])
