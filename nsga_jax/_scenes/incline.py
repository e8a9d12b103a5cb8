"""Scene ``incline``: a rigid block sliding with Coulomb friction on a tilted plane.

Built as a system: a :class:`~nsga_jax.system.RigidBody2D` (sides
``length`` along the slope and ``height`` across it), its two bottom corners
in contact (e = 0, friction ``mu``) with a tilted floor, and vertical
gravity (0, -g). The floor is the line through the origin of unit normal
n = (sin a, cos a), a = ``angle``: it descends toward +x along
d = (cos a, -sin a), the downhill direction. The block starts flush on it,
its bottom face's centre at the origin (rotation θ = -a), moving at
``velocity`` along d.

Observables: s = (r - r0) · d and ds = v · d, the distance [m] and velocity
[m/s] along the slope (downhill positive); ``rotation`` θ + a [rad], the
block's rotation relative to the slope (0 while it slides flat); the
friction force along d [N]; the energy [J]. The exact s(t), ds(t) are
:func:`~nsga_jax._exact.incline`.
"""

from __future__ import annotations

import numpy as np

from .._exact import incline
from .._results import ConfigError
from .block import block_on_line
from .friction_forces import friction_force
from .params import Param, contact_mu, friction_coefficient, positive
from .spec import SceneSpec, register

PARAMETERS = {
    "mass": positive(1.0, "mass of the block", "kg"),
    "length": positive(0.2, "side of the block along the slope", "m"),
    "height": positive(0.1, "side of the block across the slope", "m"),
    "angle": Param(0.3, "tilt of the plane from the horizontal", "rad", lo=0.0, hi=np.pi / 2, hi_open=True),
    "mu": friction_coefficient(0.2, "at the block's two bottom corners"),
    "velocity": Param(0.0, "initial velocity along the slope, downhill positive", "m/s"),
    "gravity": positive(9.81, "gravitational acceleration (vertical, downward)", "m/s^2"),
}


def check(p):
    """Refuse a block that friction could tip: the friction force F (|F| <= mu N,
    N the total normal force) acts height/2 below the centre, and the corners'
    normal forces balance its torque while |F| height <= N length; past that
    a corner lifts and the sliding (exact) solution no longer holds."""
    if p["mu"] * p["height"] > p["length"]:
        raise ConfigError(f"mu * height = {p['mu'] * p['height']:.6g} m exceeds length = {p['length']} m: "
                          "friction would tip the block over its front corner; use a squatter block")


def make(p, concrete):
    import jax
    import jax.numpy as jnp


    m, a, g = (jnp.asarray(p[k], float) for k in ("mass", "angle", "gravity"))
    length, height = jnp.asarray(p["length"], float), jnp.asarray(p["height"], float)
    normal = jnp.stack([jnp.sin(a), jnp.cos(a)])
    down = jnp.stack([jnp.cos(a), -jnp.sin(a)])
    centre = 0.5 * height * normal
    model, _ = block_on_line(m, length, height, position=centre, angle=-a, velocity=p["velocity"] * down,
                             normal=normal, mu=contact_mu(p, concrete), gravity=g, contact="slope")
    q0, v0 = model.initial_state()

    def observables(sol):
        q, v = sol.q, sol.v
        out = {"s": (q[:, :2] - q0[:2]) @ down, "ds": v[:, :2] @ down, "rotation": q[:, 2] + a,
               "omega": v[:, 2],
               "energy": jax.vmap(model.energy)(q, v)}
        if concrete["mu"] > 0:
            out["friction"] = friction_force(sol, normal) @ down
        return out

    return model, q0, v0, observables


def exact(p):
    def solution(ts):
        s, ds = incline(ts, p["angle"], p["mu"], p["gravity"], p["velocity"])
        return {"s": s, "ds": ds}

    return solution


SPEC = register(
    SceneSpec(
        name="incline",
        description="Rigid block sliding with Coulomb friction on a tilted plane (exact solution known)",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-3, "t_end": 1.0},
        make=make,
        check=check,
        exact=exact,
        observables=("s", "ds", "rotation", "omega", "friction", "energy"),
        error_observables=("s", "ds"),
        units={"s": "m", "ds": "m/s", "rotation": "rad", "omega": "rad/s", "friction": "N", "energy": "J"},
        plotted=("s", "ds", "rotation", "friction", "energy"),
    )
)
