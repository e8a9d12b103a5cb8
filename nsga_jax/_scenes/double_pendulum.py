"""Scene ``double_pendulum``: two uniform rigid rods pinned in series, the
lower rod's tip striking a vertical wall, built as a
:class:`~nsga_jax.system.System`.

Coordinates: each rod is a :class:`~nsga_jax.system.RigidBody2D`, q = [x, y, θ]
of its centre [m] and its angle [rad]; a rod lies along its body frame's
-y axis, so θ is its angle from the downward vertical, positive
counter-clockwise (the lower end toward +x). Pins hold rod 1's upper end at
the origin and rod 2's upper end at rod 1's lower end; a
:class:`~nsga_jax.system.PlaneContact` keeps rod 2's lower end (the tip) on
the starting side of the wall x = wall_x. Gravity acts along -y. The
reference is the event-driven solution in the angles θ1, θ2
(:func:`nsga_jax._exact_pendulums.double_pendulum`).
"""

from __future__ import annotations

import math

from .._results import ConfigError
from .params import Param, positive, unit_interval
from .spec import SceneSpec, register

PARAMETERS = {
    "m1": positive(1.0, "mass of rod 1 (upper)", "kg"),
    "m2": positive(1.0, "mass of rod 2 (lower)", "kg"),
    "l1": positive(0.5, "length of rod 1", "m"),
    "l2": positive(0.5, "length of rod 2", "m"),
    "gravity": Param(9.81, "gravitational acceleration (along -y)", "m/s^2", lo=0.0),
    "theta1": Param(1.2, "initial angle of rod 1 from the downward vertical, positive counter-clockwise", "rad",
                    lo=-math.pi, hi=math.pi),
    "theta2": Param(1.6, "initial angle of rod 2 from the downward vertical", "rad", lo=-math.pi, hi=math.pi),
    "omega1": Param(0.0, "initial angular velocity of rod 1", "rad/s"),
    "omega2": Param(0.0, "initial angular velocity of rod 2", "rad/s"),
    "wall_x": Param(-0.6, "x of the vertical wall; |wall_x| >= l1 (only the tip reaches it); the admissible "
                    "side is where the tip starts", "m"),
    "e": unit_interval(0.8, "Newton restitution coefficient at the wall"),
}


def _tip_x(p) -> float:
    return p["l1"] * math.sin(p["theta1"]) + p["l2"] * math.sin(p["theta2"])


def _side(concrete) -> float:
    """The admissible side of the wall, ±1: where the tip starts."""
    return math.copysign(1.0, _tip_x(concrete) - concrete["wall_x"])


def check(p):
    """Refuse a wall rod 1 could reach (the contact sees the tip only) and a tip starting on the wall."""
    if abs(p["wall_x"]) < p["l1"]:
        raise ConfigError(f"wall_x [m] = {p['wall_x']!r}: rod 1 (l1 = {p['l1']!r}) could reach the wall, which "
                          "stops rod 2's tip only; put the wall at |wall_x| >= l1")
    if abs(_tip_x(p) - p["wall_x"]) <= 1e-12 * max(1.0, p["l1"] + p["l2"]):
        raise ConfigError(f"theta1, theta2: the tip starts on the wall (x = wall_x = {p['wall_x']!r} m): the "
                          "admissible side is undefined; move the wall or change the angles")


def _placement(p):
    """Centres (2,) [m] and centre velocities (2,) [m/s] of the two rods from the angles."""
    import jax.numpy as jnp

    l1, l2, th1, th2, w1, w2 = (p[k] for k in ("l1", "l2", "theta1", "theta2", "omega1", "omega2"))
    u1, u2 = jnp.stack([jnp.sin(th1), -jnp.cos(th1)]), jnp.stack([jnp.sin(th2), -jnp.cos(th2)])
    du1, du2 = jnp.stack([jnp.cos(th1), jnp.sin(th1)]), jnp.stack([jnp.cos(th2), jnp.sin(th2)])
    c1, c2 = 0.5 * l1 * u1, l1 * u1 + 0.5 * l2 * u2
    v1, v2 = 0.5 * l1 * w1 * du1, l1 * w1 * du1 + 0.5 * l2 * w2 * du2
    return c1, c2, v1, v2


def make(p, concrete):
    import jax.numpy as jnp

    from .._system import Gravity, Pin, PlaneContact, RigidBody2D, System

    side = _side(concrete)
    c1, c2, v1, v2 = _placement(p)
    l1, l2, m1, m2 = p["l1"], p["l2"], p["m1"], p["m2"]
    system = System(dim=2)
    system.add_force("gravity", Gravity(jnp.stack([jnp.zeros(()), -jnp.asarray(p["gravity"], float)])))
    system.add_body("rod1", RigidBody2D(m1, m1 * l1**2 / 12.0, c1, p["theta1"], v1, p["omega1"]))
    system.add_body("rod2", RigidBody2D(m2, m2 * l2**2 / 12.0, c2, p["theta2"], v2, p["omega2"]))
    top1, bottom1 = jnp.stack([0.0, 0.5 * l1]), jnp.stack([0.0, -0.5 * l1])
    top2, tip = jnp.stack([0.0, 0.5 * l2]), jnp.stack([0.0, -0.5 * l2])
    system.add_joint("pivot", Pin("ground", "rod1", at_a=[0.0, 0.0], at_b=top1))
    system.add_joint("elbow", Pin("rod1", "rod2", at_a=bottom1, at_b=top2))
    system.add_contact("wall", PlaneContact("rod2", normal=[side, 0.0], origin=jnp.stack([p["wall_x"], 0.0]),
                                            e=p["e"], points=tip[None]))
    model, q0, v0 = system.build()
    wall = model.rows("contacts", "wall").start
    energy_of = model.energy

    def observables(sol):
        import jax

        q, v = sol.q, sol.v
        tip_x = q[:, 3] + 0.5 * l2 * jnp.sin(q[:, 5])  # rod 2 centre + R(θ2) [0, -l2/2]
        joints = jax.vmap(model.bilateral)(q)
        return {
            "theta1": q[:, 2], "theta2": q[:, 5], "omega1": v[:, 2], "omega2": v[:, 5],
            "tip_x": tip_x, "gap": side * (tip_x - p["wall_x"]),
            "force": sol.impulse[:, wall] / sol.h,
            "joints": jnp.max(jnp.abs(joints), axis=1),
            "energy": jax.vmap(energy_of)(q, v),
        }

    return model, q0, v0, observables


def exact(p):
    import numpy as np

    from .._exact_pendulums import double_pendulum

    def solution(ts):
        try:
            (th1, th2, w1, w2), _ = double_pendulum(
                ts, p["m1"], p["m2"], p["l1"], p["l2"], p["gravity"], p["theta1"], p["theta2"], p["omega1"],
                p["omega2"], p["wall_x"], p["e"])
        except ValueError as err:
            raise ConfigError(f"double_pendulum: no event-driven reference for this setup: {err}; compare with a "
                              "run at a smaller step instead (--ref-h)") from None
        tip_x = p["l1"] * np.sin(th1) + p["l2"] * np.sin(th2)
        return {"theta1": th1, "theta2": th2, "omega1": w1, "omega2": w2, "tip_x": tip_x}

    return solution


OBSERVABLES = ("theta1", "theta2", "omega1", "omega2", "tip_x", "gap", "force", "joints", "energy")

SPEC = register(
    SceneSpec(
        name="double_pendulum",
        description="Double pendulum of two rigid rods pinned in series, the lower tip striking a wall",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-3, "t_end": 2.0},
        make=make,
        check=check,
        exact=exact,
        observables=OBSERVABLES,
        error_observables=("theta1", "theta2", "omega1", "omega2"),
        units={"theta1": "rad", "theta2": "rad", "omega1": "rad/s", "omega2": "rad/s", "tip_x": "m", "gap": "m",
               "force": "N", "joints": "m", "energy": "J"},
    )
)
