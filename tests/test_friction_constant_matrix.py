"""Friction on a model whose velocity iteration matrix is constant (constant
mass, linear force, affine contacts): A^{-1} [g_q; g_T]^T is precomputed with
the tangential rows. A point mass sliding on a floor against Coulomb's law."""

import numpy as np

import nsga_jax
from nsga_jax.system import Gravity, PlaneContact, PointMass, System

MU, G, V0 = 0.3, 9.81, 2.0


def sliding_mass():
    s = System(dim=2)
    s.add_body("m", PointMass(1.0, position=[0.0, 0.0], velocity=[V0, 0.0]))
    s.add_contact("floor", PlaneContact("m", normal=[0.0, 1.0], origin=[0.0, 0.0], e=0.0, mu=MU))
    s.add_force("g", Gravity([0.0, -G]))
    return s.model()


def test_moreau_jean_point_mass_slides_to_coulombs_stop():
    model = sliding_mass()
    h = 1e-2
    q0, v0 = model.initial_state()
    sol = nsga_jax.simulate(model, nsga_jax.MJ(theta=0.5), 0.0, 1.0, h, q0, v0)
    q, v = np.asarray(sol.q), np.asarray(sol.v)
    assert not np.any(sol.failed_steps)
    stop = V0 / (MU * G)
    sliding = sol.ts <= stop - h
    # constant deceleration mu g while it slides: the trapezoidal position update is exact there
    np.testing.assert_allclose(v[sliding, 0], V0 - MU * G * sol.ts[sliding], rtol=0, atol=1e-12)
    np.testing.assert_allclose(q[sliding, 0], V0 * sol.ts[sliding] - MU * G * sol.ts[sliding] ** 2 / 2, atol=1e-12)
    # then it sticks where it stopped, within the stopping step's error
    assert np.all(v[sol.ts >= stop + h, 0] == 0.0)
    assert abs(q[-1, 0] - V0**2 / (2 * MU * G)) <= MU * G * h**2
    assert np.all(np.abs(q[:, 1]) < 1e-10) and np.all(np.abs(v[:, 1]) < 1e-10)
    energy = 0.5 * np.sum(v**2, axis=1) + G * q[:, 1]
    assert np.all(np.diff(energy) <= 1e-12)  # friction dissipates: the energy never grows
