"""Scene ``bouncing_ball``: a point mass dropped on a floor (exact solution known).

Built as a system: a 1D point mass (coordinate z, the height [m]), a plane
contact with the floor z = 0, and gravity."""

from __future__ import annotations

from ..exact import bouncing_ball
from .base import SceneSpec, register
from .params import Param, positive, unit_interval

PARAMETERS = {
    "mass": positive(1.0, "mass of the ball", "kg"),
    "gravity": positive(9.81, "gravitational acceleration", "m/s^2"),
    "height": Param(1.0, "initial height of the point above the floor", "m", lo=0.0,
                    note="a negative height is an initial penetration of the floor"),
    "velocity": Param(0.0, "initial vertical velocity, upward positive", "m/s"),
    "e": unit_interval(0.8, "Newton restitution coefficient"),
}


def make(p, concrete):
    import jax.numpy as jnp

    from ..system import Gravity, PlaneContact, PointMass, System

    height = jnp.reshape(jnp.asarray(p["height"], float), (1,))
    velocity = jnp.reshape(jnp.asarray(p["velocity"], float), (1,))
    system = System(dim=1)
    system.add_body("ball", PointMass(p["mass"], position=height, velocity=velocity))
    system.add_contact("floor", PlaneContact("ball", normal=[1.0], origin=[0.0], e=p["e"]))
    system.add_force("gravity", Gravity(-jnp.reshape(jnp.asarray(p["gravity"], float), (1,))))
    model = system.model()  # the scene's parameters and check() rule out an inconsistent initial state
    q0, v0 = model.initial_state()

    def observables(sol):
        z, vz = sol.q[:, 0], sol.v[:, 0]
        energy = 0.5 * p["mass"] * vz**2 + p["mass"] * p["gravity"] * z
        return {"z": z, "vz": vz, "force": sol.impulse[:, 0] / sol.h, "energy": energy}

    return model, q0, v0, observables


def exact(p):
    def solution(ts):
        z, vz = bouncing_ball(ts, p["height"], p["velocity"], p["gravity"], p["e"])
        return {"z": z, "vz": vz}

    return solution


SPEC = register(
    SceneSpec(
        name="bouncing_ball",
        description="Point mass dropped on a rigid floor (exact solution known)",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-3, "t_end": 3.0},
        make=make,
        exact=exact,
        observables=("z", "vz", "force", "energy"),
        error_observables=("z", "vz"),
        units={"z": "m", "vz": "m/s", "force": "N", "energy": "J"},
    )
)
