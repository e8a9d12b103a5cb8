"""Scene ``rocking_block``: Housner's rocking block, a rigid rectangle rocking on its corners.

Built as a system: a :class:`~nsga_jax.system.RigidBody2D` (q = [x, y, θ]:
the centre [m] and the rotation θ [rad], counterclockwise positive) of width
b and height h_b, its two bottom corners in contact with the floor y = 0
(e = 0, Coulomb friction ``mu``, high by default so that the corners stick),
and gravity. It starts at rest tilted by θ = ``tilt`` on one bottom corner
(the left one for tilt > 0, the right one for tilt < 0), that corner on the
floor at x = ∓b/2.

On a corner the block turns about it: θ'' = -p² sin(α sgn θ - θ), with
α = atan(b/h_b) the slenderness angle, R = ½ √(b² + h_b²) and
p² = m g R / I_O = 3 g / (4 R). When it lands on the other corner, that
corner sticks without rebound and the angular momentum about it is kept:
ω+/ω- = 1 - (3/2) sin²α (Housner 1963), :func:`~nsga_jax._exact.housner_ratio`;
:func:`~nsga_jax._exact.rocking_impacts` gives the speeds before and after
each impact.
"""

from __future__ import annotations

import numpy as np

from .._results import ConfigError
from .block import block_on_line
from .friction_forces import friction_force
from .params import Param, contact_mu, friction_coefficient, positive
from .spec import SceneSpec, register

PARAMETERS = {
    "mass": positive(1.0, "mass of the block", "kg"),
    "width": positive(0.2, "width b of the block", "m"),
    "height": positive(0.6, "height h_b of the block", "m"),
    "tilt": Param(0.15, "initial rocking angle θ (> 0: on the left corner, < 0: on the right one), "
                  "|tilt| < atan(width/height)", "rad", lo=-np.pi / 2, hi=np.pi / 2, lo_open=True, hi_open=True),
    "mu": friction_coefficient(1.0, "at the two bottom corners (high: the corners stick)"),
    "gravity": positive(9.81, "gravitational acceleration", "m/s^2"),
}


def check(p):
    alpha = float(np.arctan2(p["width"], p["height"]))
    if abs(p["tilt"]) >= alpha:
        raise ConfigError(f"tilt [rad] must be in (-{alpha:.6g}, {alpha:.6g}) (atan(width/height): beyond it "
                          f"the block topples), got {p['tilt']!r}")


def corner_velocities(q, v, corners):
    """Velocities (rows, k, 2) [m/s] of the body-frame points ``corners`` (k, 2)
    of a planar rigid body with coordinates ``q``, ``v`` (rows, 3)."""
    import jax.numpy as jnp

    c, s = jnp.cos(q[:, 2]), jnp.sin(q[:, 2])
    rx = c[:, None] * corners[:, 0] - s[:, None] * corners[:, 1]  # R X, (rows, k)
    ry = s[:, None] * corners[:, 0] + c[:, None] * corners[:, 1]
    omega = v[:, 2:3]
    return jnp.stack([v[:, 0:1] - omega * ry, v[:, 1:2] + omega * rx], axis=-1)


def make(p, concrete):
    import jax
    import jax.numpy as jnp


    m, b, hb, g, tilt = (jnp.asarray(p[k], float) for k in ("mass", "width", "height", "gravity", "tilt"))
    side = 1.0 if concrete["tilt"] >= 0 else -1.0  # the pivot: left corner (+1) or right corner (-1)
    pivot = jnp.stack([-side * 0.5 * b, -0.5 * hb])  # body frame
    c, s = jnp.cos(tilt), jnp.sin(tilt)
    centre = jnp.stack([-side * 0.5 * b, jnp.zeros_like(b)]) - jnp.stack([c * pivot[0] - s * pivot[1],
                                                                           s * pivot[0] + c * pivot[1]])
    model, corners = block_on_line(m, b, hb, position=centre, angle=tilt, velocity=jnp.zeros(2),
                                   normal=jnp.array([0.0, 1.0]), mu=contact_mu(p, concrete), gravity=g,
                                   contact="floor")
    q0, v0 = model.initial_state()

    def observables(sol):
        q, v = sol.q, sol.v
        slip = corner_velocities(q, v, corners)[:, :, 0]
        out = {"theta": q[:, 2], "omega": v[:, 2], "x": q[:, 0], "y": q[:, 1],
               "energy": jax.vmap(model.energy)(q, v),
               "slip_left": slip[:, 0], "slip_right": slip[:, 1]}
        if concrete["mu"] > 0:
            out["friction"] = friction_force(sol, [0.0, 1.0])[:, 0]
        return out

    return model, q0, v0, observables


SPEC = register(
    SceneSpec(
        name="rocking_block",
        description="Housner's rocking block: a rigid rectangle rocking on its corners, omega+/omega- = "
                    "1 - 1.5 sin^2(alpha) at each impact",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-3, "t_end": 2.0},
        make=make,
        check=check,
        observables=("theta", "omega", "x", "y", "energy", "slip_left", "slip_right", "friction"),
        error_observables=("theta", "omega"),
        units={"theta": "rad", "omega": "rad/s", "x": "m", "y": "m", "energy": "J", "slip_left": "m/s",
               "slip_right": "m/s", "friction": "N"},
        plotted=("theta", "omega", "x", "energy", "slip_left", "slip_right", "friction"),
    )
)
