"""Generalized-α alone (no constraints): order of accuracy and spectral radius."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import Oscillator

import nsga_jax as nj
from nsga_jax._metrics import observed_order


def test_coefficients_match_eq35():
    c = nj.GenAlphaCoefficients.from_rho_inf(0.8)
    am, af = (2 * 0.8 - 1) / 1.8, 0.8 / 1.8
    g = 0.5 + af - am
    assert np.allclose([c.alpha_m, c.alpha_f, c.gamma, c.beta], [am, af, g, 0.25 * (g + 0.5) ** 2])


@pytest.mark.parametrize("rho_inf", [0.0, 0.5, 0.8, 1.0])
def test_linear_oscillator_second_order(rho_inf):
    model = Oscillator(m=2.0, k=2.0 * (2 * np.pi) ** 2)  # period 1 s
    errors, hs = [], [1 / 40, 1 / 80, 1 / 160, 1 / 320]
    for h in hs:
        sol = nj.simulate(model, nj.DS(rho_inf=rho_inf, tol_r=1e-12, tol_f=1e-12), 0.0, 2.0, h, [1.0], [0.0])
        exact = np.cos(2 * np.pi * sol.ts)
        errors.append(np.abs(sol.q[:, 0] - exact).max())
    order = observed_order(hs, errors)
    assert 1.9 < order < 2.2, (order, errors)


def _amplification(rho_inf, omega_h):
    """One-step map of (q, v, v̇̃, a) for the oscillator at ω h, by forward-mode AD."""
    h = 1.0
    model = Oscillator(m=1.0, k=omega_h**2)
    scheme = nj.DS(rho_inf=rho_inf, tol_r=1e-13, tol_f=1e-13)
    ops = scheme.prepare(model, jnp.asarray(h), jnp.zeros(()))

    def step(x):
        state = nj.StepState(t=jnp.zeros(()), q=x[0:1], v=x[1:2], vd=x[2:3], a=x[3:4])
        new, _ = scheme.step(model, ops, state, jnp.asarray(h))
        return jnp.concatenate([new.q, new.v, new.vd, new.a])

    return np.asarray(jax.jacfwd(step)(jnp.array([1.0, 0.3, -0.7, 0.2])))


@pytest.mark.parametrize("rho_inf", [0.0, 0.3, 0.8, 1.0])
def test_spectral_radius_at_infinity(rho_inf):
    rho = np.abs(np.linalg.eigvals(_amplification(rho_inf, 1e6))).max()
    assert rho == pytest.approx(rho_inf, abs=2e-3)


def test_spectral_radius_low_frequency_is_one():
    rho = np.abs(np.linalg.eigvals(_amplification(0.8, 1e-3))).max()
    assert rho == pytest.approx(1.0, abs=1e-6)
