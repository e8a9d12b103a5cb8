"""Event-aware gradients (``trajectory(..., adjoint="event")``) against the exact
continuous-time derivatives: the bouncing ball (closed form) and the rigid
pendulum against a wall (event-driven reference, diffrax)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import nsga_jax as nj
from nsga_jax.exact import bouncing_ball, rigid_pendulum
from nsga_jax.scenes import parametrize

G = 9.81


def loss_fn(scene, overrides, names, observable, t_data, y_data, h, t_end, adjoint):
    """Mean square mismatch of one observable, sampled at t_data, as a function of the parameters."""
    n = int(round(t_end / h))
    params, build = parametrize(scene, {**overrides, "h": h}, names)
    ts = jnp.arange(n + 1) * h

    def loss(p):
        model, q0, v0, observe = build(p)
        y = observe(nj.trajectory(model, nj.DS(), 0.0, h, n, q0, v0, adjoint=adjoint))[observable]
        return jnp.mean((jnp.interp(t_data, ts, y) - y_data) ** 2)

    return params, loss


def central(f, x, step):
    return (f(x + step) - f(x - step)) / (2 * step)


# ------------------------------------------------------------------ ball

BALL_T = np.arange(0.0, 1.5 + 1e-12, 0.01)
BALL_DATA = bouncing_ball(BALL_T, 1.0, 0.0, G, 0.8)[0]


def ball_exact_loss(e, h0):
    return float(np.mean((bouncing_ball(BALL_T, h0, 0.0, G, e)[0] - BALL_DATA) ** 2))


def test_ball_event_gradient_converges_to_the_exact_derivative():
    exact = np.array([central(lambda e: ball_exact_loss(e, 1.0), 0.85, 1e-6),
                      central(lambda h0: ball_exact_loss(0.85, h0), 1.0, 1e-6)])
    errors = []
    for h in (1e-3, 3e-4, 1e-4):
        params, loss = loss_fn("bouncing_ball", {"e": 0.85, "height": 1.0}, ["e", "height"], "z",
                               BALL_T, BALL_DATA, h, 1.5, "event")
        g = jax.grad(loss)(params)
        grad = np.array([float(g["e"]), float(g["height"])])
        errors.append(np.abs(grad / exact - 1.0))
        if h == 1e-3:  # forward mode gives the same derivative
            fwd = jax.jvp(lambda e: loss({**params, "e": e}), (params["e"],), (jnp.ones(()),))[1]
            assert float(fwd) == pytest.approx(grad[0], rel=1e-10)
    errors = np.array(errors)
    assert np.all(errors[0] < 0.05), errors
    assert np.all(errors[-1] < errors[0]) and np.all(errors[-1] < 0.01), errors


def test_discrete_gradient_misses_the_impact_time_sensitivity():
    params, loss = loss_fn("bouncing_ball", {"e": 0.85, "height": 1.0}, ["height"], "z",
                           BALL_T, BALL_DATA, 1e-3, 1.5, "discrete")
    exact = central(lambda h0: ball_exact_loss(0.85, h0), 1.0, 1e-6)
    assert abs(float(jax.grad(loss)(params)["height"])) < 0.05 * abs(exact)


def test_away_from_impacts_both_adjoints_agree():
    t = np.arange(0.0, 0.4 + 1e-12, 0.01)  # the first impact is at 0.45 s
    grads = []
    for adjoint in ("discrete", "event"):
        params, loss = loss_fn("bouncing_ball", {"e": 0.85, "height": 1.0, "velocity": 0.3}, ["height", "velocity"],
                               "z", t, np.zeros_like(t), 1e-3, 0.4, adjoint)
        grads.append(jax.grad(loss)(params))
    for k in grads[0]:
        assert float(grads[1][k]) == pytest.approx(float(grads[0][k]), rel=1e-13, abs=1e-15)


# -------------------------------------------------------------- pendulum

PEND_T = np.arange(0.0, 1.0 + 1e-12, 0.01)  # one impact, at 0.638 s
PENDULUM = dict(length=1.0, gravity=G, angle=1.0, omega=0.0, e=0.7)


def pendulum_x(wall_x):
    return rigid_pendulum(PEND_T, wall_x=wall_x, **PENDULUM)[0][0]


def test_pendulum_event_gradient_in_wall_position():
    data = pendulum_x(-0.3)
    wall = -0.28
    exact = central(lambda w: float(np.mean((pendulum_x(w) - data) ** 2)), wall, 1e-5)
    params, loss = loss_fn("rigid_pendulum", {"wall_x": wall, "e": 0.7}, ["wall_x"], "x",
                           PEND_T, data, 1e-3, 1.0, "event")
    grad = float(jax.grad(loss)(params)["wall_x"])
    assert grad == pytest.approx(exact, rel=0.05)
    params, loss = loss_fn("rigid_pendulum", {"wall_x": wall, "e": 0.7}, ["wall_x"], "x",
                           PEND_T, data, 1e-3, 1.0, "discrete")
    assert abs(float(jax.grad(loss)(params)["wall_x"]) / exact - 1.0) > 0.2  # what the event term adds


def test_unknown_adjoint_is_refused():
    with pytest.raises(nj.ConfigError, match=r"adjoint must be one of 'discrete', 'event'"):
        nj.trajectory(nj.BouncingBall(m=1.0, gravity=G, e=0.5), nj.DS(), 0.0, 1e-3, 10, jnp.ones(1),
                      jnp.zeros(1), adjoint="saltation")
