"""Event-aware gradients (``integrate(..., adjoint=ImpactTimeAdjoint())``) against the exact
continuous-time derivatives: the bouncing ball (closed form) and the rigid
pendulum against a wall (event-driven reference, diffrax)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from reference_models import BouncingBall

import nsga_jax as nj
from nsga_jax._adjoint import adjoint_named
from nsga_jax._exact import bouncing_ball, rigid_pendulum
from nsga_jax.scenes import parametrize

G = 9.81
EVENT, DISCRETE = nj.ImpactTimeAdjoint(), nj.DiscreteAdjoint()


def loss_fn(scene, overrides, names, observable, t_data, y_data, n_steps, adjoint, scheme=None):
    """``loss(p, h)``: mean square mismatch of one observable at t_data, after
    n_steps of size h (h is traced: one compilation serves every step size
    whose run covers t_data)."""
    params, build = parametrize(scene, overrides, names)

    def loss(p, h):
        model, q0, v0, observables = build(p)
        sol = nj.integrate(model, scheme or nj.DS(), 0.0, n_steps * h, h, q0, v0, n_steps=n_steps, adjoint=adjoint)
        y = observables(sol)[observable]
        return jnp.mean((jnp.interp(t_data, h * jnp.arange(n_steps + 1), y) - y_data) ** 2)

    return params, loss


def central(f, x, step):
    return (f(x + step) - f(x - step)) / (2 * step)


# ------------------------------------------------------------------ ball

BALL_T = np.arange(0.0, 1.5 + 1e-12, 0.01)
BALL_DATA = bouncing_ball(BALL_T, 1.0, 0.0, G, 0.8)[0]


def ball_exact_loss(e, h0):
    return float(np.mean((bouncing_ball(BALL_T, h0, 0.0, G, e)[0] - BALL_DATA) ** 2))


BALL = {"e": 0.85, "height": 1.0}


def ball_exact_gradient():
    return np.array([central(lambda e: ball_exact_loss(e, 1.0), 0.85, 1e-6),
                     central(lambda h0: ball_exact_loss(0.85, h0), 1.0, 1e-6)])


def as_array(g):
    return np.array([float(g["e"]), float(g["height"])])


def test_ball_event_gradient_converges_to_the_exact_derivative():
    exact = ball_exact_gradient()
    params, loss = loss_fn("bouncing_ball", BALL, ["e", "height"], "z", BALL_T, BALL_DATA, 15000, EVENT)
    grad = jax.jit(jax.grad(loss))
    errors = np.array([np.abs(as_array(grad(params, h)) / exact - 1.0) for h in (1e-3, 3e-4, 1e-4)])
    assert np.all(errors[0] < 0.05), errors
    assert np.all(errors[-1] < errors[0]) and np.all(errors[-1] < 0.01), errors
    # the discrete map's own derivative misses the impact instants' motion: all of dL/dh0
    _, discrete = loss_fn("bouncing_ball", BALL, ["e", "height"], "z", BALL_T, BALL_DATA, 1500, DISCRETE)
    g = as_array(jax.grad(discrete)(params, 1e-3))
    assert abs(g[1]) < 0.05 * abs(exact[1]) and abs(g[0] / exact[0] - 1.0) > 0.1


def test_event_gradient_forward_equals_reverse():
    params, loss = loss_fn("bouncing_ball", BALL, ["e"], "z", BALL_T, BALL_DATA, 1500, EVENT)
    reverse = float(jax.grad(loss)(params, 1e-3)["e"])
    forward = jax.jvp(lambda e: loss({"e": e}, 1e-3), (params["e"],), (jnp.ones(()),))[1]
    assert float(forward) == pytest.approx(reverse, rel=1e-10)


@pytest.mark.parametrize("scheme", [nj.DSn(), nj.MJ()], ids=["DSn", "MJ"])
def test_other_schemes_event_gradient(scheme):
    # Moreau-Jean detects an impact after the gap went negative: the impact instant is then
    # a root before t_n, and the rebuild still gives the continuous derivative.
    params, loss = loss_fn("bouncing_ball", BALL, ["e", "height"], "z", BALL_T, BALL_DATA, 1500, EVENT, scheme)
    np.testing.assert_allclose(as_array(jax.grad(loss)(params, 1e-3)), ball_exact_gradient(), rtol=0.05)


def test_away_from_impacts_both_adjoints_agree():
    t = np.arange(0.0, 0.4 + 1e-12, 0.01)  # the first impact is at 0.45 s
    grads = []
    for adjoint in (nj.DiscreteAdjoint(), EVENT):
        params, loss = loss_fn("bouncing_ball", {**BALL, "velocity": 0.3}, ["height", "velocity"], "z", t,
                               np.zeros_like(t), 400, adjoint)
        grads.append(jax.grad(loss)(params, 1e-3))
    for k in grads[0]:
        assert float(grads[1][k]) == pytest.approx(float(grads[0][k]), rel=1e-13, abs=1e-15)


# -------------------------------------------------------------- pendulum

PEND_T = np.arange(0.0, 1.0 + 1e-12, 0.01)  # one impact, at 0.638 s
PENDULUM = dict(length=1.0, gravity=G, angle=1.0, omega=0.0, e=0.7)


def pendulum_x(wall_x):
    return rigid_pendulum(PEND_T, wall_x=wall_x, **PENDULUM)[0][0]


def test_pendulum_event_gradient_in_wall_position():
    # a nonlinear bilateral constraint (the rod) holds through the impact
    data = pendulum_x(-0.3)
    wall = -0.28
    exact = central(lambda w: float(np.mean((pendulum_x(w) - data) ** 2)), wall, 1e-5)
    params, loss = loss_fn("rigid_pendulum", {"wall_x": wall, "e": 0.7}, ["wall_x"], "x", PEND_T, data, 1000,
                           EVENT)
    grad = float(jax.grad(loss)(params, 1e-3)["wall_x"])
    assert grad == pytest.approx(exact, rel=0.05)


def test_unknown_adjoint_is_refused():
    # the command line's names of the adjoints
    with pytest.raises(nj.ConfigError, match=r"adjoint must be one of 'discrete', 'event'"):
        adjoint_named("saltation")
    assert isinstance(adjoint_named("event"), nj.ImpactTimeAdjoint)


@pytest.mark.parametrize("given, shown", [("event", "str 'event'"),
                                          (nj.ImpactTimeAdjoint, "the class ImpactTimeAdjoint")])
def test_adjoint_must_be_an_instance(given, shown):
    with pytest.raises(TypeError, match=rf"adjoint must be an adjoint instance: nsga_jax.DiscreteAdjoint\(\) "
                                        rf"or nsga_jax.ImpactTimeAdjoint\(\), got {shown}"):
        nj.integrate(BouncingBall(m=1.0, gravity=G, e=0.5), nj.DS(), 0.0, 0.01, 1e-3, jnp.ones(1),
                     jnp.zeros(1), adjoint=given)
