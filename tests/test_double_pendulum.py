"""Double pendulum of two rigid rods striking a wall (scene ``double_pendulum``,
built as a System): its equations against the minimal-coordinate reference,
and the DS scheme against the event-driven solution."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import nsga_jax
from nsga_jax._exact_pendulums import _mass, _rhs, double_pendulum, double_pendulum_energy
from nsga_jax.scenes import configure, load_scene

KEYS = ("m1", "m2", "l1", "l2", "gravity", "theta1", "theta2", "omega1", "omega2", "wall_x", "e")
P = dict(m1=1.3, m2=0.7, l1=0.5, l2=0.8, gravity=9.81)


def coordinates(p, theta):
    """The system's q = [x1, y1, θ1, x2, y2, θ2] of the rods at the angles θ (2,), written anew."""
    th1, th2 = theta
    l1, l2 = p["l1"], p["l2"]
    return jnp.stack([0.5 * l1 * jnp.sin(th1), -0.5 * l1 * jnp.cos(th1), th1,
                      l1 * jnp.sin(th1) + 0.5 * l2 * jnp.sin(th2), -l1 * jnp.cos(th1) - 0.5 * l2 * jnp.cos(th2), th2])


def traced_scene(overrides):
    """The validated parameters and ``make`` of the scene: the model built from
    traced float parameters inside a jitted function compiles once (an eager
    build would run its initial-state check operation by operation)."""
    configured = configure("double_pendulum", overrides)
    concrete = configured.parameters
    floats = {k: jnp.asarray(v, float) for k, v in concrete.items()}
    return concrete, floats, lambda p: configured.spec.make(p, concrete)


def test_reference_equations_are_the_systems():
    """At random states: the pins hold at q(θ); the system's mass matrix and
    forces projected on the angles (Jᵀ M J, Jᵀ (f - M J̇ θ̇)) are the
    reference's M(θ) and Lagrange right-hand side; the wall's row of g_q
    mapped to the angles is ±W; the model's energy is the reference's; the
    initial state is q(θ0), J θ̇0, clear of the wall."""
    p, floats, make = traced_scene({**P, "omega1": 1.5, "omega2": -2.0})
    args = jnp.array([p["m1"], p["m2"], p["l1"], p["l2"], p["gravity"], p["wall_x"], 1.0])

    @jax.jit
    def both_sides(floats, theta, omega):
        model, q0, v0, _ = make(floats)
        q = coordinates(p, theta)
        J = jax.jacfwd(lambda th: coordinates(p, th))(theta)
        v = J @ omega
        M, G = model.mass(q), model.constraint_jacobian(q)
        # q̈ = J θ̈ + (d²q/ds² along θ̇): the second term by nested forward derivatives
        curvature = jax.jvp(lambda th: jax.jvp(lambda x: coordinates(p, x), (th,), (omega,))[1], (theta,), (omega,))[1]
        acc = jnp.linalg.solve(J.T @ M @ J, J.T @ (model.force(q, v, 0.0) - M @ curvature))
        system = dict(pins=model.bilateral(q), pin_rates=G[:4] @ v, mass=J.T @ M @ J, acc=acc, wall=G[4] @ J,
                      energy=model.energy(q, v), side=model.contacts[0].normal[0], q0=q0, v0=v0,
                      gap0=model.unilateral(q0)[0])
        theta0, omega0 = jnp.stack([p["theta1"], p["theta2"]]), jnp.stack([p["omega1"], p["omega2"]])
        W = jnp.stack([p["l1"] * jnp.cos(theta[0]), p["l2"] * jnp.cos(theta[1])])
        reference = dict(mass=_mass(args, *theta), acc=_rhs(0.0, jnp.concatenate([theta, omega]), args)[2:], wall=W,
                         q0=coordinates(p, theta0),
                         v0=jax.jacfwd(lambda th: coordinates(p, th))(theta0) @ omega0)
        return system, reference

    rng = np.random.default_rng(1)
    for _ in range(3):
        theta, omega = rng.uniform(-2, 2, 2), rng.uniform(-3, 3, 2)
        system, reference = both_sides(floats, jnp.asarray(theta), jnp.asarray(omega))
        np.testing.assert_allclose(system["pins"], 0.0, atol=1e-15)
        np.testing.assert_allclose(system["pin_rates"], 0.0, atol=1e-14)
        np.testing.assert_allclose(system["mass"], reference["mass"], rtol=1e-14)
        np.testing.assert_allclose(system["acc"], reference["acc"], rtol=1e-12)
        np.testing.assert_allclose(system["wall"], system["side"] * reference["wall"], atol=1e-15)
        energy = double_pendulum_energy(*theta, *omega, *(p[k] for k in KEYS[:5]))
        assert float(system["energy"]) == pytest.approx(float(energy), rel=1e-13, abs=1e-13)
    np.testing.assert_allclose(system["q0"], reference["q0"], atol=1e-15)
    np.testing.assert_allclose(system["v0"], reference["v0"], atol=1e-14)
    assert float(system["gap0"]) > 0


def test_structure_and_checks():
    p, floats, make = traced_scene({})
    model = eqx.filter_eval_shape(lambda f: make(f)[0], floats)  # structure only: nothing is evaluated
    assert (model.n_dof, model.n_bilateral, model.n_unilateral) == (6, 4, 1)
    assert model.constant_mass and model.linear_force and not model.linear_constraints
    assert model.joint_names == ("pivot", "elbow") and model.contact_names == ("wall",)
    with pytest.raises(nsga_jax.ConfigError, match="rod 1 .* could reach the wall"):
        configure("double_pendulum", {"wall_x": -0.4})
    with pytest.raises(nsga_jax.ConfigError, match="starts on the wall"):
        configure("double_pendulum", {"wall_x": -1.0, "theta1": -np.pi / 2, "theta2": -np.pi / 2})
    with pytest.raises(nsga_jax.ConfigError, match="e must be in"):
        configure("double_pendulum", {"e": 1.5})


# ------------------------------------------- the DS scheme against the reference

H = (2e-3, 5e-4)


@pytest.fixture(scope="module")
def runs():
    """The default scene to t = 1.2 s (one impact, at t* ≈ 0.605 s) at two
    steps, with the event-driven reference on each grid."""
    out = {}
    for h in H:
        scene = load_scene("double_pendulum", {"h": h, "t_end": 1.2})
        sol = scene.run(progress=False)
        assert sol.stats["failed_steps"] == 0
        ref, impacts = double_pendulum(sol.ts, *(scene.parameters[k] for k in KEYS))
        assert len(impacts) == 1
        out[h] = scene, sol, dict(zip(("theta1", "theta2", "omega1", "omega2"), ref)), impacts[0]
    return out


def test_reference_keeps_energy_between_impacts_and_loses_newtons_share(runs):
    scene, sol, ref, (t_star, before, after, impulse) = runs[H[-1]]
    p = scene.parameters
    energy = double_pendulum_energy(ref["theta1"], ref["theta2"], ref["omega1"], ref["omega2"],
                                    *(p[k] for k in KEYS[:5]))
    pre, post = sol.ts < t_star, sol.ts > t_star
    assert np.ptp(energy[pre]) < 1e-9 and np.ptp(energy[post]) < 1e-9  # [J]
    assert after == pytest.approx(-p["e"] * before, rel=1e-12)
    # Λ = m_eff (1 + e) |w⁻|, and the energy lost is ½ m_eff (1 - e²) w⁻²
    lost = energy[pre][-1] - energy[post][0]
    assert lost == pytest.approx(0.5 * impulse * (1.0 - p["e"]) * abs(before), rel=1e-8)


def test_angles_converge_to_the_reference_before_and_after_the_impact(runs):
    errors = {}
    for h, (scene, sol, ref, impact) in runs.items():
        t_star = impact[0]
        shift = np.ceil(t_star / h) * h - t_star  # the scheme places the impact at the end of its step
        pre, post = sol.ts < t_star, sol.ts > t_star + h
        for k in ("theta1", "theta2"):
            err = np.abs(sol.observables[k] - ref[k])
            errors[h, k] = err[pre].max(), err[post].max()
            assert errors[h, k][0] < 30.0 * h**2, (h, k, errors[h, k])  # second order while smooth; seen 23 h²
            assert errors[h, k][1] < 30.0 * (shift + h**2), (h, k, errors[h, k])  # seen 21 (shift + h²)
        omega_err = max(np.abs(sol.observables[k] - ref[k])[post].max() for k in ("omega1", "omega2"))
        assert omega_err < 150.0 * h, (h, omega_err)  # first order: seen 87 h and 97 h [rad/s]
    for k in ("theta1", "theta2"):
        assert errors[H[0], k][0] > 10.0 * errors[H[1], k][0]  # h / 4: before the impact about 16 times smaller
        assert errors[H[0], k][1] > 2.0 * errors[H[1], k][1]   # after: the impact's time shift shrinks with h


def test_joints_hold_and_the_tip_never_penetrates(runs):
    for h, (scene, sol, _, impact) in runs.items():
        assert np.abs(sol.records.bilateral).max() < 1e-8        # pins, position level [m]
        assert np.abs(sol.records.bilateral_rate).max() < 1e-8   # pins, velocity level [m/s]
        assert sol.observables["joints"].max() < 1e-8
        assert sol.gap.min() > -1e-10 and sol.observables["gap"].min() > -1e-10
        force = sol.observables["force"]
        hits = np.nonzero(force > 0)[0]
        assert len(hits) == 1 and sol.ts[hits[0] - 1] < impact[0] <= sol.ts[hits[0]] + 1e-12
        assert force.min() >= 0.0


def test_energy_never_grows_at_the_impact(runs):
    for h, (scene, sol, ref, impact) in runs.items():
        energy = sol.observables["energy"]
        k = int(np.nonzero(sol.impulse[:, 4] > 0)[0][0])
        assert energy[:k].max() <= energy[0] + 100.0 * h**2      # smooth phase: O(h²) drift at most; seen 2 h²
        assert energy[k:].max() < energy[k - 1]                   # the impact dissipates (e < 1) for good
        # the energy lost converges to the reference's at first order in h (seen 14 h [J/s])
        p = scene.parameters
        lost = 0.5 * impact[3] * (1.0 - p["e"]) * abs(impact[1])
        assert abs(energy[k - 1] - energy[k] - lost) < 20.0 * h
