"""Scene ``bouncing_ball``: a ball dropped on a floor (exact vertical motion known).

Built as a system. By default (``mu = 0``, ``vx = 0``, ``spin = 0``) a 1D
point mass (coordinate z [m], the height of the ball's lowest point), a plane
contact with the floor z = 0, and gravity: the motion is vertical and the
ball's radius plays no part.

Asked for friction, a horizontal velocity or a spin, the ball is a planar
rigid body (a :class:`~nsga_jax.system.RigidBody2D`, q = [x, y, θ]: the
centre [m] and the rotation [rad], counterclockwise positive) of inertia
J = (2/5) m r², a solid sphere's (the ball rolls in the x-y plane), with a
plane contact of radius r at its centre, so friction acts at its lowest
point and the spin matters: the slip velocity there is vx + ω r, and rolling
without slip is vx = -ω r. The vertical motion is the 1D one (z = y - r),
so the exact z(t), vz(t) hold in both cases."""

from __future__ import annotations

from .._exact import bouncing_ball
from .friction_forces import friction_force
from .params import Param, contact_mu, friction_coefficient, positive, unit_interval
from .spec import SceneSpec, register

PARAMETERS = {
    "mass": positive(1.0, "mass of the ball", "kg"),
    "gravity": positive(9.81, "gravitational acceleration", "m/s^2"),
    "height": Param(1.0, "initial height of the ball's lowest point above the floor", "m", lo=0.0,
                    note="a negative height is an initial penetration of the floor"),
    "velocity": Param(0.0, "initial vertical velocity, upward positive", "m/s"),
    "e": unit_interval(0.8, "Newton restitution coefficient"),
    "mu": friction_coefficient(0.0, "at the ball's lowest point (> 0: a planar ball)"),
    "vx": Param(0.0, "initial horizontal velocity of the centre (!= 0: a planar ball)", "m/s"),
    "spin": Param(0.0, "initial angular velocity ω, counterclockwise positive (!= 0: a planar ball)", "rad/s"),
    "radius": positive(0.1, "radius of the planar ball (inertia (2/5) m r², a solid sphere's)", "m"),
}


def planar(concrete) -> bool:
    """Whether the ball is built in the plane (friction, a horizontal velocity or a spin asked)."""
    return concrete["mu"] > 0 or concrete["vx"] != 0 or concrete["spin"] != 0


def make(p, concrete):
    import jax.numpy as jnp

    from .._system import Gravity, PlaneContact, PointMass, System

    if planar(concrete):
        return _make_planar(p, concrete)
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


def _make_planar(p, concrete):
    """The planar ball: a disk of a solid sphere's inertia, its centre r above its lowest point."""
    import jax.numpy as jnp

    from .._system import Gravity, PlaneContact, RigidBody2D, System

    m, r, g = (jnp.asarray(p[k], float) for k in ("mass", "radius", "gravity"))
    inertia = 0.4 * m * r**2
    system = System(dim=2)
    system.add_body("ball", RigidBody2D(
        m, inertia, position=jnp.stack([jnp.zeros_like(r), p["height"] + r]),
        velocity=jnp.stack([jnp.asarray(p["vx"], float), jnp.asarray(p["velocity"], float)]),
        angular_velocity=p["spin"]))
    system.add_contact("floor", PlaneContact("ball", normal=[0.0, 1.0], origin=[0.0, 0.0], e=p["e"], radius=r,
                                             mu=contact_mu(p, concrete)))
    system.add_force("gravity", Gravity(jnp.stack([jnp.zeros_like(g), -g])))
    model = system.model()
    q0, v0 = model.initial_state()

    def observables(sol):
        x, y, vx, vz, omega = sol.q[:, 0], sol.q[:, 1], sol.v[:, 0], sol.v[:, 1], sol.v[:, 2]
        energy = 0.5 * m * (vx**2 + vz**2) + 0.5 * inertia * omega**2 + m * g * y
        out = {"z": y - r, "vz": vz, "x": x, "vx": vx, "omega": omega, "slip": vx + omega * r,
               "force": sol.impulse[:, 0] / sol.h, "energy": energy}
        if concrete["mu"] > 0:
            out["friction"] = friction_force(sol, [0.0, 1.0])[:, 0]
        return out

    return model, q0, v0, observables


def exact(p):
    def solution(ts):
        z, vz = bouncing_ball(ts, p["height"], p["velocity"], p["gravity"], p["e"])
        return {"z": z, "vz": vz}

    return solution


SPEC = register(
    SceneSpec(
        name="bouncing_ball",
        description="Point mass dropped on a rigid floor (exact solution known); with mu, vx or spin "
                    "a planar ball that slides and rolls",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-3, "t_end": 3.0},
        make=make,
        exact=exact,
        observables=("z", "vz", "force", "energy", "x", "vx", "omega", "slip", "friction"),
        error_observables=("z", "vz"),
        units={"z": "m", "vz": "m/s", "force": "N", "energy": "J", "x": "m", "vx": "m/s", "omega": "rad/s",
               "slip": "m/s", "friction": "N"},
        plotted=("z", "vz", "force", "energy", "x", "vx", "omega", "slip", "friction"),
    )
)
