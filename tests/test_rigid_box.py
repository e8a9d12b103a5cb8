"""Rigid box in natural coordinates: free-flight invariants, rigidity, and the
motion against an independent rigid-body ODE solution (diffrax)."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from nsga_jax.scenes import load_scene


@pytest.mark.parametrize("rho_inf, energy_tol", [(1.0, 1e-6), (0.8, 2e-6)])
def test_free_flight_conserves_energy_and_angular_momentum(rho_inf, energy_tol):
    # with rho_inf < 1 the first step (a_0 = v̇_0, Algorithm 1 line 3) costs about
    # 1e-6 of the kinetic energy at 60 rad/s, h = 1e-4; rho_inf = 1 has no numerical dissipation
    scene = load_scene("rigid_box", {"floor": "off", "gravity": 0.0, "h": 1e-4, "t_end": 0.2, "rho_inf": rho_inf})
    sol = scene.run()
    model, box = scene.model, scene.model.body("box")  # the box's coordinates are all of q
    energy = jax.jit(jax.vmap(model.energy))(sol.q, sol.v)
    momentum = jax.jit(jax.vmap(box.angular_momentum))(sol.q, sol.v)
    assert np.abs(energy / energy[0] - 1.0).max() <= energy_tol
    assert np.abs(momentum - momentum[0]).max() <= 1e-6 * np.linalg.norm(momentum[0])
    # rigidity constraints after every step, at position and velocity level
    assert np.abs(np.asarray(sol.records.bilateral)).max() < 1e-10
    assert np.abs(np.asarray(sol.records.bilateral_rate)).max() < 1e-10


def euler_reference(scene, ts):
    """Newton-Euler equations of the box (rotation matrix and body angular velocity)."""
    J = jnp.asarray(scene.model.body("box").inertia)
    g = scene.parameters["gravity"]

    def rhs(t, y, args):
        rd, R, Om = y[3:6], y[6:15].reshape(3, 3), y[15:]
        W = jnp.array([[0.0, -Om[2], Om[1]], [Om[2], 0.0, -Om[0]], [-Om[1], Om[0], 0.0]])
        Omd = jnp.linalg.solve(J, -jnp.cross(Om, J @ Om))
        return jnp.concatenate([rd, jnp.array([0.0, 0.0, -g]), (R @ W).reshape(-1), Omd])

    p = scene.parameters
    y0 = jnp.concatenate([jnp.array([p["x0"], p["y0"], p["z0"]]), jnp.array([p["vx0"], p["vy0"], p["vz0"]]),
                          jnp.eye(3).reshape(-1), jnp.array([p["omega_x"], p["omega_y"], p["omega_z"]])])
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(rhs), diffrax.Dopri8(), 0.0, float(ts[-1]), 1e-4, y0,
        saveat=diffrax.SaveAt(ts=jnp.asarray(ts)),
        stepsize_controller=diffrax.PIDController(rtol=1e-12, atol=1e-12), max_steps=100_000,
    )
    return np.asarray(sol.ys[:, :3]), np.asarray(sol.ys[:, 6:15]).reshape(-1, 3, 3)


def test_flight_before_impact_matches_rigid_body_ode():
    errors = {}
    for h in (2e-4, 1e-4):
        scene = load_scene("rigid_box", {"h": h, "t_end": 0.34})  # the first impact is at t ≈ 0.42 s
        sol = scene.run()
        assert np.all(sol.impulse[:, 6:] == 0.0)  # no contact yet
        every = int(round(2e-3 / h))
        ts = sol.ts[::every]
        r_ref, R_ref = euler_reference(scene, ts)
        np.testing.assert_allclose(sol.q[::every, :3], r_ref, atol=1e-10)
        errors[h] = np.abs(sol.observables["rotation"][::every] - R_ref).max()
    assert errors[1e-4] < 5e-4
    assert np.log2(errors[2e-4] / errors[1e-4]) == pytest.approx(2.0, abs=0.3)  # second order in flight
