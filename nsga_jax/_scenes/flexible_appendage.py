"""Scene ``flexible_appendage``: a flexible beam clamped to a spinning rigid hub,
whose tip strikes a stop, built from parts (:class:`nsga_jax.system.System`).

Bodies, in the order of the coordinates:

- ``hub``: a rigid disc (:class:`~nsga_jax.system.RigidBody2D`, q = x, y, θ
  of its centre), pinned to the ground at the origin (``hub = "pinned"``, a
  rotating hub) or free (``"free"``, a floating body); inertia m R² / 2.
- ``beam``: the appendage, a geometrically exact planar beam
  (:class:`~nsga_jax.system.Beam2D`, per node x, y, θ), clamped by node 0 to
  the hub's rim at body coordinates (R, 0) (:class:`~nsga_jax.system.Weld`:
  position and angle), radial, initially straight and unstressed.

Everything starts as a rigid rotation about the hub's centre at
``hub_omega``. The stop is the horizontal line y = ``stop_y``, which the
beam's tip (its last node) strikes from below
(:class:`~nsga_jax.system.PlaneContact`, gap ``stop_y - y_tip``, Newton
restitution ``e``). Gravity acts along -y (zero by default: a horizontal plane).
"""

from __future__ import annotations

import math

from .._results import ConfigError
from .params import Param, nonnegative, positive, unit_interval
from .spec import SceneSpec, register

PARAMETERS = {
    "hub_radius": positive(0.2, "hub radius R: the clamp is on the rim", "m"),
    "hub_mass": positive(10.0, "hub mass (a uniform disc: inertia m R^2 / 2)", "kg"),
    "hub": Param("pinned", "hub pinned to the ground at its centre, or free", kind="choice",
                 choices=("pinned", "free")),
    "length": positive(1.0, "beam length", "m"),
    "n_elements": Param(6, "number of beam elements", kind="int", lo=1, hi=1000),
    "E": positive(2.1e11, "Young's modulus of the beam", "Pa"),
    "nu": Param(0.3, "Poisson's ratio of the beam", lo=-1.0, lo_open=True, hi=0.5, hi_open=True),
    "rho": positive(7800.0, "density of the beam", "kg/m^3"),
    "area": positive(1e-4, "cross-section area A (a 50 mm x 2 mm strip)", "m^2"),
    "second_moment": positive(3.333e-11, "second moment of area I, bending in the plane of motion", "m^4"),
    "shear_factor": Param(5.0 / 6.0, "shear area ratio As/A", lo=0.0, lo_open=True, hi=1.0),
    "angle": Param(0.0, "initial hub angle; the beam points along it", "rad", lo=-math.pi, hi=math.pi),
    "hub_omega": Param(2.0, "initial angular velocity of the hub and beam (counter-clockwise)", "rad/s"),
    "stop_y": Param(0.6, "y of the horizontal stop line the tip strikes from below", "m"),
    "e": unit_interval(0.5, "Newton restitution coefficient at the stop"),
    "gravity": nonnegative(0.0, "gravitational acceleration (along -y)", "m/s^2"),
}

OBSERVABLES = ("hub_angle", "hub_omega", "tip_x", "tip_y", "tip_deflection", "gap", "force", "constraint",
               "energy")
UNITS = {"hub_angle": "rad", "hub_omega": "rad/s", "tip_x": "m", "tip_y": "m", "tip_deflection": "m", "gap": "m",
         "force": "N", "constraint": "m", "energy": "J"}


def check(p):
    y_tip = (p["hub_radius"] + p["length"]) * math.sin(p["angle"])
    if not p["stop_y"] - y_tip > 1e-12 * p["length"]:
        raise ConfigError(f"the tip starts at y = {y_tip:.6g} m, at or above the stop (stop_y = {p['stop_y']} m); "
                          "the stop must lie above it")


def make(p, concrete):
    import jax
    import jax.numpy as jnp

    from .._system import Beam2D, Gravity, Pin, PlaneContact, RigidBody2D, System, Weld

    R, a, om = p["hub_radius"], p["angle"], p["hub_omega"]
    radial = jnp.stack([jnp.cos(a), jnp.sin(a)])
    zero = jnp.zeros_like(radial[0])
    system = System(dim=2)
    system.add_body("hub", RigidBody2D(mass=p["hub_mass"], inertia=0.5 * p["hub_mass"] * R**2,
                                       position=jnp.zeros(2), angle=a, angular_velocity=om))
    system.add_body("beam", Beam2D(E=p["E"], nu=p["nu"], rho=p["rho"], area=p["area"],
                                   second_moment=p["second_moment"], length=p["length"],
                                   n_elements=concrete["n_elements"], position=R * radial, angle=a,
                                   velocity=R * om * jnp.stack([-radial[1], radial[0]]), angular_velocity=om,
                                   shear_factor=p["shear_factor"]))
    if concrete["hub"] == "pinned":
        system.add_joint("axle", Pin("ground", "hub"))
    system.add_joint("clamp", Weld("hub", "beam", at_a=jnp.stack([R, 0.0 * R]), node_b=0))
    system.add_contact("stop", PlaneContact("beam", normal=[0.0, -1.0], origin=jnp.stack([zero, zero + p["stop_y"]]),
                                            e=p["e"], nodes=[-1]))
    system.add_force("gravity", Gravity(jnp.stack([zero, -p["gravity"]])))
    model, q0, v0 = system.build()

    hub, beam, clamp = model.coordinates("hub"), model.coordinates("beam"), model.rows("joints", "clamp")
    energy = jax.vmap(model.energy)
    bilateral = jax.vmap(model.bilateral)

    def observables(sol):
        q, v = sol.q, sol.v
        xh, th = q[:, hub][:, :2], q[:, hub][:, 2]
        along = jnp.stack([jnp.cos(th), jnp.sin(th)], axis=1)  # the rigid line of the clamped beam
        tip = q[:, beam][:, -3:-1]
        relative = tip - (xh + R * along)
        return {
            "hub_angle": th, "hub_omega": v[:, hub][:, 2],
            "tip_x": tip[:, 0], "tip_y": tip[:, 1],
            "tip_deflection": along[:, 0] * relative[:, 1] - along[:, 1] * relative[:, 0],
            "gap": p["stop_y"] - tip[:, 1],
            "force": sol.impulse[:, -1] / sol.h,
            "constraint": jnp.max(jnp.abs(bilateral(q)[:, clamp]), axis=1),
            "energy": energy(q, v),
        }

    return model, q0, v0, observables


SPEC = register(
    SceneSpec(
        name="flexible_appendage",
        description="Flexible beam clamped to a spinning rigid hub, its tip striking a stop",
        parameters=PARAMETERS,
        solver_defaults={"h": 5e-4, "t_end": 1.5},
        make=make,
        check=check,
        observables=OBSERVABLES,
        error_observables=("hub_omega", "tip_deflection"),
        units=UNITS,
        plotted=("hub_angle", "hub_omega", "tip_y", "tip_deflection", "gap", "force", "constraint", "energy"),
    )
)
