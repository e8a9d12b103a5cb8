"""Gradients through trajectories with impacts (implicit differentiation of each
Newton solve, active set frozen) against central finite differences, between
modes and under vmap; CS refuses to be differentiated."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import nsga_jax
from nsga_jax.scenes import load_scene, make_scheme, parametrize

FD_STEP = 1e-6  # relative


def scene_loss(name, names, overrides, n_steps, observable, scheme=None):
    """``(params, loss)``: loss(p) = mean square of one observable over n_steps."""
    scene = load_scene(name, overrides)
    params, build = parametrize(name, overrides, names)
    scheme = scheme or make_scheme(scene.solver)
    h = scene.solver["h"]

    def loss(p):
        model, q0, v0, observables = build(p)
        sol = nsga_jax.integrate(model, scheme, 0.0, n_steps * h, h, q0, v0, n_steps=n_steps)
        return jnp.mean(observables(sol)[observable] ** 2)

    return params, loss


def central_differences(value, params, k):
    """d value / d params[k], central, with a relative step FD_STEP."""
    step = FD_STEP * max(abs(float(params[k])), 1e-3)
    plus, minus = dict(params), dict(params)
    plus[k] = params[k] + step
    minus[k] = params[k] - step
    return (float(value(plus)) - float(value(minus))) / (2 * step)


def check_against_fd(params, loss, rtol=1e-5):
    value_and_grad = jax.jit(jax.value_and_grad(loss))
    value, grad = value_and_grad(params)
    assert np.isfinite(float(value))
    for k in params:
        fd = central_differences(lambda p: value_and_grad(p)[0], params, k)
        assert abs(float(grad[k])) > 1e-8, f"{k}: zero gradient proves nothing"
        np.testing.assert_allclose(float(grad[k]), fd, rtol=rtol, err_msg=k)
    return grad


def test_bar_tip_displacement_against_fd():
    # 40-element bar through the contact (t ~ 0.5 s to 1.17 s, while the tip rests on the wall)
    # and past the rebound
    params, loss = scene_loss("impacting_bar", ["E", "velocity"], {"n_elements": 40, "h": 1e-3}, 1500, "tip_u")
    check_against_fd(params, loss)


def test_ball_height_against_fd():
    # one impact (t ~ 0.45 s) in the window, at the same step under the perturbation
    params, loss = scene_loss("bouncing_ball", ["e", "height"], {"h": 1e-3}, 900, "z")
    grad = check_against_fd(params, loss)
    assert float(grad["e"]) > 0  # a higher rebound raises the mean square height


def test_rigid_pendulum_against_fd():
    # The derivative is exact at the converged Newton iterate; the loss itself is only as
    # smooth as the Newton tolerance allows (at the default 1e-5 the two agree to 6e-6 here),
    # so the check tightens the tolerance and asks for more.
    scheme = nsga_jax.DS(rho_inf=0.8, tol_r=1e-12, tol_f=1e-12)
    params, loss = scene_loss("rigid_pendulum", ["length", "wall_x"], {"h": 1e-3}, 1500, "x", scheme=scheme)
    check_against_fd(params, loss, rtol=1e-7)


def test_rigid_box_restitution_against_fd():
    params, loss = scene_loss("rigid_box", ["e"], {"h": 1e-3}, 690, "gap_5")
    check_against_fd(params, loss)


@pytest.mark.parametrize("scheme", [nsga_jax.DSn(), nsga_jax.MJ()], ids=["dsn", "mj"])
def test_other_schemes_against_fd(scheme):
    params, loss = scene_loss("bouncing_ball", ["e", "height"], {"h": 1e-3}, 900, "z",
                              scheme=scheme)
    check_against_fd(params, loss)


def test_reverse_equals_forward():
    params, loss = scene_loss("bouncing_ball", ["e", "height"], {"h": 1e-3}, 900, "z")
    reverse = jax.jit(jax.grad(loss))(params)
    forward = jax.jit(jax.jacfwd(loss))(params)
    for k in params:
        np.testing.assert_allclose(float(reverse[k]), float(forward[k]), rtol=1e-12, err_msg=k)
    # a jvp along one direction is the directional derivative
    tangent = {"e": jnp.asarray(0.3), "height": jnp.asarray(-1.2)}
    _, jvp = jax.jit(lambda p, t: jax.jvp(loss, (p,), (t,)))(params, tangent)
    expected = sum(float(reverse[k]) * float(tangent[k]) for k in params)
    np.testing.assert_allclose(float(jvp), expected, rtol=1e-12)


def test_bar_reverse_equals_forward():
    params, loss = scene_loss("impacting_bar", ["E", "velocity"], {"n_elements": 20, "h": 2e-3}, 750, "tip_u")
    reverse = jax.jit(jax.grad(loss))(params)
    forward = jax.jit(jax.jacfwd(loss))(params)
    for k in params:
        np.testing.assert_allclose(float(reverse[k]), float(forward[k]), rtol=1e-11, err_msg=k)


def test_vmap_of_grad_equals_grad():
    params, loss = scene_loss("bouncing_ball", ["e", "height"], {"h": 1e-3}, 900, "z")
    grad = jax.jit(jax.grad(loss))
    batch = {"e": jnp.asarray([0.5, 0.7, 0.9]), "height": jnp.asarray([1.2, 1.0, 0.8])}
    batched = jax.jit(jax.vmap(jax.grad(loss)))(batch)
    for i in range(3):
        single = grad({k: v[i] for k, v in batch.items()})
        for k in params:
            np.testing.assert_allclose(float(batched[k][i]), float(single[k]), rtol=1e-12, err_msg=f"{k}[{i}]")


def test_coupled_scheme_refuses_differentiation():
    model, q0, v0, _ = parametrize("bouncing_ball")[1](parametrize("bouncing_ball")[0])
    with pytest.raises(nsga_jax.ConfigError, match="CS is not differentiable"):
        nsga_jax.integrate(model, nsga_jax.CS(), 0.0, 0.01, 1e-3, q0, v0)


def test_checkpointing_choices_give_the_same_gradient():
    params, build = parametrize("bouncing_ball", {"h": 1e-3}, ["e", "height"])

    def loss(p, every, steps):
        model, q0, v0, observables = build(p)
        sol = nsga_jax.integrate(model, nsga_jax.DS(), 0.0, 0.9, 1e-3, q0, v0, checkpoint_every=every,
                                 checkpoint_steps=steps)
        return jnp.mean(observables(sol)["z"] ** 2)

    grads = [jax.jit(jax.grad(lambda p, e=e, s=s: loss(p, e, s)))(params)
             for e, s in ((None, False), (7, True))]
    for g in grads[1:]:
        for k in params:
            np.testing.assert_allclose(float(g[k]), float(grads[0][k]), rtol=1e-12, err_msg=k)


def test_spectral_radius_is_differentiable():
    # rho_inf is a field of the scheme: build the scheme inside the loss
    params, build = parametrize("impacting_bar", {"h": 2e-3, "n_elements": 20}, ["e"])
    model, q0, v0, observables = build(params)

    def loss(p):
        sol = nsga_jax.integrate(model, nsga_jax.DS(rho_inf=p["rho_inf"]), 0.0, 1.5, 2e-3, q0, v0)
        return jnp.mean(observables(sol)["tip_v"] ** 2)

    check_against_fd({"rho_inf": jnp.asarray(0.8)}, loss, rtol=1e-5)
