"""Scene ``bouncing_ball``: a point mass dropped on a floor (exact solution known)."""

from __future__ import annotations

import numpy as np

from ..exact import bouncing_ball
from ..models.point_mass import BouncingBall
from .base import Scene, SceneSpec, register
from .params import Param, positive, unit_interval

PARAMETERS = {
    "mass": positive(1.0, "mass of the ball", "kg"),
    "gravity": positive(9.81, "gravitational acceleration", "m/s^2"),
    "height": Param(1.0, "initial height of the point above the floor", "m", lo=0.0,
                    note="a negative height is an initial penetration of the floor"),
    "velocity": Param(0.0, "initial vertical velocity, upward positive", "m/s"),
    "e": unit_interval(0.8, "Newton restitution coefficient"),
}


def build(p, solver) -> Scene:
    model = BouncingBall(m=p["mass"], gravity=p["gravity"], e=p["e"])

    def observe(sol):
        z, vz = sol.q[:, 0], sol.v[:, 0]
        energy = 0.5 * p["mass"] * vz**2 + p["mass"] * p["gravity"] * z
        return {"z": z, "vz": vz, "force": sol.impulse[:, 0] / sol.h, "energy": energy}

    def exact(ts):
        z, vz = bouncing_ball(ts, p["height"], p["velocity"], p["gravity"], p["e"])
        return {"z": z, "vz": vz}

    return Scene("bouncing_ball", model, np.array([p["height"]]), np.array([p["velocity"]]),
                 p, solver, observe, exact)


SPEC = register(
    SceneSpec(
        name="bouncing_ball",
        description="Point mass dropped on a rigid floor (exact solution known)",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-3, "t_end": 3.0},
        build=build,
        observables=("z", "vz", "force", "energy"),
        error_observables=("z", "vz"),
    )
)
