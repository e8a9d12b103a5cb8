"""Impact-time derivatives through frictional impacts
(``integrate(..., adjoint=ImpactTimeAdjoint())`` on models with Coulomb
friction) against the exact continuous-time derivatives of a ball: a disk
(planar, friction segment) and a sphere (in space, friction disk) thrown with
spin onto a floor, slipping through the impact, sticking at it, and sliding
on after it.

The exact motion (unit mass, J = 2/5 m r², a solid sphere's, friction at the
lowest point): the ball lands at t* = (v_y0 + |v_n|)/g with |v_n| =
sqrt(v_y0² + 2 g h0) and takes the normal impulse P_N = (1 + e)|v_n|; the
slip s of its lowest point changes by 7/2 P_T (and its centre by P_T), so
it sticks (s⁺ = 0, P_T = -2/7 s⁻) where that needs |P_T| <= μ P_N and slips
otherwise (P_T = -μ P_N s⁻/|s⁻|, e.g. v_x⁺ = v_x - μ (1 + e)|v_n|). With
e = 0 it stays on the floor and a slip left after the impact decelerates at
μ g (7/2 μ g for the slip) until it rolls.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import nsga_jax as nj
from nsga_jax._impact_time_friction import frictional_impact
from nsga_jax._integrators.model_terms import restitution
from nsga_jax.scenes import parametrize
from nsga_jax.system import Gravity, PlaneContact, RigidBody2D, RigidBody3D, System

G, R = 9.81, 0.1
EVENT, DISCRETE = nj.ImpactTimeAdjoint(), nj.DiscreteAdjoint()
N_STEPS = 60  # h is traced: one compilation serves every step size (and every parameter value)
STEPS = (1e-3, 3e-4, 1e-4)
# thrown down at 2.4 m/s from 14.2 mm, the ball lands at t* = 5.85 ms, 0.85, 0.15 and 0.05 ms after
# the last step time before it at these step sizes: the rebuild's error is of the order of that offset
THROW = {"height": 0.014208, "velocity": -2.4}


def exact_ball(u0, s0, vy0, h0, mu, e, t):
    """Centre velocity u (k,), slip s (k,) and centre displacement x (k,)
    along the floor, and the vertical velocity, at time t after one impact
    (module docstring); k = 1 or 2."""
    vn = np.sqrt(vy0**2 + 2 * G * h0)
    t_hit = (vy0 + vn) / G
    assert t_hit < t
    p_n = (1 + e) * vn
    p_t = -s0 / 3.5
    if np.linalg.norm(p_t) > mu * p_n:
        p_t = -mu * p_n * s0 / np.linalg.norm(s0)
    u, s = u0 + p_t, s0 + 3.5 * p_t
    rest = t - t_hit
    x = u0 * t_hit + u * rest
    if e > 0:
        return u, s, x, e * vn - G * rest
    speed = np.linalg.norm(s)
    if speed > 0:  # sliding on, decelerated by mu g (the tests stop before it rolls)
        decel = mu * G * s / speed
        assert np.linalg.norm(3.5 * decel * rest) < speed
        u, s, x = u - decel * rest, s - 3.5 * decel * rest, x - 0.5 * decel * rest**2
    return u, s, x, 0.0


def central(f, p, k, step=1e-7):
    """Central difference of f (a dict of parameters -> array) in p[k]."""
    up, down = dict(p), dict(p)
    up[k], down[k] = p[k] + step, p[k] - step
    return (f(up) - f(down)) / (2 * step)


def compare(jac, exact_fn, p0, names):
    """[(got, exact)] per step size: the adjoint's Jacobian of the outputs in
    ``names`` at t_N = N_STEPS h and central differences of the closed form."""
    params = {k: jnp.asarray(float(p0[k])) for k in names}
    out = []
    for h in STEPS:
        J = jac(params, h)
        got = np.stack([np.asarray(J[k]) for k in names], axis=1)
        exact = np.stack([central(lambda q: exact_fn(q, N_STEPS * h), p0, k) for k in names], axis=1)
        out.append((got, exact))
    return out


def relative_errors(pairs):
    """max |got - exact| per step size, each output relative to its largest derivative."""
    return [float(np.max(np.abs(got - exact) / np.abs(exact).max(axis=1)[:, None])) for got, exact in pairs]


# ------------------------------------------------------- the impact law alone

def disk_impact(mu, e, v_minus):
    """v⁺ of the frictional impact law alone (no time stepping): the planar
    ball touching the floor, arriving with v⁻ = (v_x, v_y, ω)."""
    s = System(dim=2)
    s.add_body("ball", RigidBody2D(1.0, 0.4 * R**2, position=[0.0, R]))
    s.add_contact("floor", PlaneContact("ball", normal=[0.0, 1.0], origin=[0.0, 0.0], e=e, radius=R, mu=mu))
    model = s.model()
    q, _ = model.initial_state()
    G = model.constraint_jacobian(q)
    return frictional_impact(model, model.mass(q), G, q, v_minus, jnp.ones((1,), bool),
                             restitution(model, q.dtype))


DISK_IMPACT = jax.jit(lambda mu, e, v: (disk_impact(mu, e, v), jax.jacfwd(disk_impact, argnums=(0, 1, 2))(mu, e, v),
                                        jax.grad(lambda m, w: disk_impact(m, e, w)[0], argnums=(0, 1))(mu, v)))
"""v⁺, its forward-mode Jacobian in (mu, e, v⁻) and the reverse-mode gradient of v_x⁺ in (mu, v⁻)."""


@pytest.mark.parametrize("case", ["slip", "stick"])
def test_frictional_impact_law_and_its_derivative(case):
    mu, e, v_minus = (0.2, 0.5, jnp.array([1.0, -2.4, 30.0])) if case == "slip" else \
        (0.8, 0.5, jnp.array([0.5, -2.4, -2.0]))
    slip = float(v_minus[0] + R * v_minus[2])
    if case == "slip":  # P_T = -mu (1 + e) |v_n|: v_x⁺ = v_x - mu (1 + e) |v_n|, ω⁺ = ω + r P_T / J
        exact = np.array([1.0 - 0.3 * 2.4, 1.2, 30.0 - 0.3 * 2.4 / (0.4 * R)])
        d_mu = np.array([-1.5 * 2.4, 0.0, -1.5 * 2.4 / (0.4 * R)])
        d_e = np.array([-0.2 * 2.4, 2.4, -0.2 * 2.4 / (0.4 * R)])
        d_vy = np.array([0.3, -0.5, 0.3 / (0.4 * R)])  # |v_n| = -v_y
        d_vx = np.array([1.0, 0.0, 0.0])
    else:  # P_T = -2/7 s⁻: the slip stops, whatever mu, e and v_n
        exact = np.array([0.5 - slip / 3.5, 1.2, -2.0 - slip / (1.4 * R)])
        d_mu, d_e = np.zeros(3), np.array([0.0, 2.4, 0.0])
        d_vy = np.array([0.0, -0.5, 0.0])
        d_vx = np.array([5 / 7, 0.0, -1 / (1.4 * R)])
    v_plus, (J_mu, J_e, J_v), g = DISK_IMPACT(jnp.asarray(mu), jnp.asarray(e), v_minus)
    np.testing.assert_allclose(v_plus, exact, rtol=1e-12, atol=1e-12)
    for got, want in ((J_mu, d_mu), (J_e, d_e), (J_v[:, 1], d_vy), (J_v[:, 0], d_vx)):
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-10)
    # reverse mode agrees with forward mode
    assert float(g[0]) == pytest.approx(float(J_mu[0]), rel=1e-12, abs=1e-12)
    np.testing.assert_allclose(g[1], J_v[0], rtol=1e-12, atol=1e-12)


# ---------------------------------------------------------------- the disk

DISK_NAMES = ["mu", "e", "velocity", "height", "vx", "spin"]
SLIP = {"mu": 0.2, "e": 0.5, **THROW, "vx": 1.0, "spin": 30.0}


def disk_exact(p, t):
    """(v_x, ω, v_y, x) at t of the planar ball (slip v_x + ω r)."""
    u, s, x, vy = exact_ball(np.array([p["vx"]]), np.array([p["vx"] + p["spin"] * R]), p["velocity"],
                             p["height"], p["mu"], p["e"], t)
    return np.array([u[0], (s[0] - u[0]) / R, vy, x[0]])


SCHEMES = {"DS": nj.DS(), "DSn": nj.DSn(), "MJ": nj.MJ()}


@functools.cache
def disk_jacobian(adjoint, scheme="DS"):
    """jit(jacfwd) of (v_x, ω, v_y, x)(t_N) in DISK_NAMES and h, for any values
    with the same structure (a planar ball with friction)."""
    _, build = parametrize("bouncing_ball", {"radius": R, **SLIP}, DISK_NAMES)

    def final(p, h):
        model, q0, v0, _ = build(p)
        sol = nj.integrate(model, SCHEMES[scheme], 0.0, N_STEPS * h, h, q0, v0, n_steps=N_STEPS, adjoint=adjoint)
        return jnp.stack([sol.v[-1, 0], sol.v[-1, 2], sol.v[-1, 1], sol.q[-1, 0]])

    return jax.jit(jax.jacfwd(final))


def disk_case(p0, adjoint=EVENT, scheme="DS"):
    return compare(disk_jacobian(adjoint, scheme), disk_exact, p0, DISK_NAMES)


def test_disk_slipping_through_the_impact():
    pairs = disk_case(SLIP)
    got, exact = pairs[-1]
    vn = np.hypot(2.4, np.sqrt(2 * G * THROW["height"]))
    # the closed form's derivatives: v_x⁺ = v_x - μ (1 + e)|v_n|
    for k, value in (("mu", -1.5 * vn), ("e", -0.2 * vn), ("velocity", -0.3 * -2.4 / vn)):
        assert exact[0, DISK_NAMES.index(k)] == pytest.approx(value, rel=1e-6)
        assert got[0, DISK_NAMES.index(k)] == pytest.approx(value, rel=1e-6)
    errors = relative_errors(pairs)
    print("disk slip: max relative error at h =", STEPS, errors)
    # a rigid body's free flight is quadratic in its coordinates, the rebuild exact: round-off
    assert max(errors) < 1e-6, errors


@pytest.mark.parametrize("scheme", ["DSn", "MJ"])
def test_disk_slipping_through_the_impact_with_the_other_schemes(scheme):
    """DSn's and Moreau–Jean's (θ = 1/2) free flight under constant gravity is
    exact as DS's is, so their rebuilt impacts, friction included, give the
    continuous derivative to round-off too."""
    errors = relative_errors(disk_case(SLIP, scheme=scheme))
    print(f"disk slip, {scheme}: max relative error at h =", STEPS, errors)
    assert max(errors) < 1e-6, errors


def test_disk_sticking_at_the_impact():
    pairs = disk_case({**SLIP, "mu": 0.8, "vx": 0.5, "spin": -2.0})
    got, exact = pairs[-1]
    # stick: v_x⁺ = v_x - 2/7 s⁻, independent of mu, e and the landing speed
    assert exact[0, DISK_NAMES.index("vx")] == pytest.approx(5 / 7, rel=1e-6)
    assert exact[0, DISK_NAMES.index("spin")] == pytest.approx(-R * 2 / 7, rel=1e-6)
    np.testing.assert_allclose(got[:2, :4], 0.0, atol=1e-10)
    errors = relative_errors(pairs)
    print("disk stick: max relative error at h =", STEPS, errors)
    assert max(errors) < 1e-6, errors


def test_disk_landing_and_sliding_on():
    # e = 0: the contact stays closed and the slip left after the impact is decelerated by mu g;
    # the landing instant moves the position x at t_N (velocities: the total friction impulse is
    # mu times the total normal one, whenever the ball lands)
    pairs = disk_case({**SLIP, "e": 0.0, "mu": 0.1, "spin": 60.0})
    got, exact = pairs[-1]
    assert abs(exact[3, DISK_NAMES.index("height")]) > 1e-3
    # (not in e: at e = 0 a central difference crosses to e < 0; nor v_y, zero)
    columns = [k for k, name in enumerate(DISK_NAMES) if name != "e"]
    errors = relative_errors([(g[np.ix_([0, 1, 3], columns)], x[np.ix_([0, 1, 3], columns)]) for g, x in pairs])
    print("disk slide-on: max relative error at h =", STEPS, errors)
    assert max(errors) < 1e-6, errors


def test_discrete_adjoint_misses_the_impact_instant():
    # the discrete map's derivative holds the impact at its step: dv_x/dv_y0 is mu (1 + e), not
    # mu (1 + e) |v_y0| / |v_n| as in continuous time
    got, exact = disk_case(SLIP, DISCRETE)[-1]
    k = DISK_NAMES.index("velocity")
    assert got[0, k] == pytest.approx(0.3, rel=1e-6) and abs(got[0, k] / exact[0, k] - 1.0) > 0.02


# -------------------------------------------------------------- the sphere

SPHERE_NAMES = ["mu", "e", "height", "velocity", "vx", "vy", "wx", "wy"]
SPHERE = {"mu": 0.2, "e": 0.5, **THROW, "vx": 1.0, "vy": 0.5, "wx": 20.0, "wy": -30.0}


def sphere_model(p):
    """A sphere (radius R, 1 kg, J = 2/5 m r²) above the floor z = 0, thrown
    down with horizontal velocity and spin, with friction: natural coordinates
    (6 rigidity constraints), friction disk (friction_dim 2)."""
    s = System(dim=3)
    s.add_body("ball", RigidBody3D(1.0, jnp.full((3,), 0.4 * R**2), position=jnp.stack([0.0, 0.0, p["height"] + R]),
                                   velocity=jnp.stack([p["vx"], p["vy"], p["velocity"]]),
                                   angular_velocity=jnp.stack([p["wx"], p["wy"], 0.0])))
    s.add_contact("floor", PlaneContact("ball", normal=[0.0, 0.0, 1.0], origin=[0.0, 0.0, 0.0], e=p["e"],
                                        radius=R, mu=p["mu"]))
    s.add_force("g", Gravity([0.0, 0.0, -G]))
    return s.model()


def sphere_exact(p, t):
    """(v_x, v_y, v_z, x, y) of the centre at t; the slip of the lowest point
    is (v_x - ω_y r, v_y + ω_x r)."""
    u0 = np.array([p["vx"], p["vy"]])
    s0 = u0 + R * np.array([-p["wy"], p["wx"]])
    u, _, x, vz = exact_ball(u0, s0, p["velocity"], p["height"], p["mu"], p["e"], t)
    return np.array([u[0], u[1], vz, x[0], x[1]])


def test_sphere_slipping_through_the_impact():
    def final(p, h):
        model = sphere_model(p)
        q0, v0 = model.initial_state()
        sol = nj.integrate(model, nj.DS(), 0.0, N_STEPS * h, h, q0, v0, n_steps=N_STEPS, adjoint=EVENT)
        return jnp.concatenate([sol.v[-1, :3], sol.q[-1, :2]])

    pairs = compare(jax.jit(jax.jacfwd(final)), sphere_exact, SPHERE, SPHERE_NAMES)
    errors = relative_errors(pairs)
    print("sphere slip: max relative error at h =", STEPS, errors)
    # natural coordinates: the rotation's quadratic extrapolation to the impact instant is first
    # order, and so is the derivative of the slip's direction
    assert errors[0] < 1e-2 and errors[-1] < errors[1] < errors[0], errors
