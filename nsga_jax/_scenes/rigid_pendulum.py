"""Scene ``rigid_pendulum``: a point mass on a rigid rod (a nonlinear bilateral
constraint in Cartesian coordinates) swinging against a vertical wall.

Built as a system: a planar point mass (x, y) [m], a ``Distance`` joint of
the rod's length to the pivot at the ground's origin, a plane contact with
the wall (normal towards the side where the mass starts), and gravity."""

from __future__ import annotations

import math

from .._results import ConfigError
from .params import Param, positive, unit_interval
from .spec import SceneSpec, register

PARAMETERS = {
    "mass": positive(1.0, "mass of the bob", "kg"),
    "length": positive(1.0, "rod length", "m"),
    "gravity": Param(9.81, "gravitational acceleration (downward)", "m/s^2", lo=0.0),
    "angle": Param(1.0, "initial angle from the downward vertical, positive towards +x", "rad",
                   lo=-math.pi, hi=math.pi),
    "omega": Param(0.0, "initial angular velocity (positive: counter-clockwise)", "rad/s"),
    "wall_x": Param(-0.3, "x position of the vertical wall; the admissible side is where the mass starts", "m"),
    "e": unit_interval(0.7, "Newton restitution coefficient at the wall"),
}


def _side(concrete) -> float:
    return math.copysign(1.0, concrete["length"] * math.sin(concrete["angle"]) - concrete["wall_x"])


def check(p):
    if abs(p["length"] * math.sin(p["angle"]) - p["wall_x"]) <= 1e-12 * max(1.0, p["length"]):
        raise ConfigError(
            f"the mass starts on the wall (x = wall_x = {p['wall_x']}): the admissible side is "
            "undefined; move the wall or change the initial angle"
        )


def make(p, concrete):
    import jax.numpy as jnp

    from .._system import Distance, Gravity, PlaneContact, PointMass, System

    length, th, om = p["length"], p["angle"], p["omega"]
    side = _side(concrete)
    system = System(dim=2)
    system.add_body("bob", PointMass(p["mass"], position=length * jnp.stack([jnp.sin(th), -jnp.cos(th)]),
                                     velocity=length * om * jnp.stack([jnp.cos(th), jnp.sin(th)])))
    system.add_joint("rod", Distance("bob", "ground", length=length))
    wall = jnp.stack([jnp.asarray(p["wall_x"], float), jnp.zeros(())])
    system.add_contact("wall", PlaneContact("bob", normal=[side, 0.0], origin=wall, e=p["e"]))
    system.add_force("gravity", Gravity(jnp.stack([jnp.zeros(()), -jnp.asarray(p["gravity"], float)])))
    model = system.model()  # the scene's parameters and check() rule out an inconsistent initial state
    q0, v0 = model.initial_state()

    def observables(sol):
        x, y, vx, vy = sol.q[:, 0], sol.q[:, 1], sol.v[:, 0], sol.v[:, 1]
        energy = 0.5 * p["mass"] * (vx**2 + vy**2) + p["mass"] * p["gravity"] * y
        return {
            "x": x, "y": y, "vx": vx, "vy": vy,
            "gap": side * (x - p["wall_x"]),
            "constraint": jnp.hypot(x, y) - length,
            "force": sol.impulse[:, 1] / sol.h,
            "energy": energy,
        }

    return model, q0, v0, observables


SPEC = register(
    SceneSpec(
        name="rigid_pendulum",
        description="Point mass on a rigid rod (nonlinear bilateral constraint) hitting a wall",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-3, "t_end": 5.0},
        make=make,
        check=check,
        observables=("x", "y", "vx", "vy", "gap", "constraint", "force", "energy"),
        error_observables=("x", "vx"),
        units={"x": "m", "y": "m", "vx": "m/s", "vy": "m/s", "gap": "m", "constraint": "m", "force": "N",
               "energy": "J"},
    )
)
