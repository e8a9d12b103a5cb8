"""Scene ``slider_crank``: a planar slider-crank with a flexible connecting rod
whose slider strikes a stop, built from parts (:class:`nsga_jax.system.System`).

Bodies, in the order of the coordinates:

- ``crank``: a rigid bar (:class:`~nsga_jax.system.RigidBody2D`, q = x, y, θ
  of its centre of mass), pinned to the ground at the origin; its tip is at
  ``crank_length`` (cos θ, sin θ). Driven by a constant torque or free.
- ``rod``: the connecting rod, a geometrically exact planar beam
  (:class:`~nsga_jax.system.Beam2D`, per node x, y, θ), initially straight
  and unstressed; node 0 pinned to the crank's tip, its last node to the slider.
- ``slider``: a point mass (:class:`~nsga_jax.system.PointMass`, q = x, y)
  on the horizontal line y = 0 (:class:`~nsga_jax.system.Slider`).

The stop is a vertical line x = ``stop_x`` that the slider strikes from the
left (:class:`~nsga_jax.system.PlaneContact`, gap ``stop_x - x``, Newton
restitution ``e``). Gravity acts along -y. The initial state is the rigid
mechanism's: the crank at ``crank_angle`` turning at ``crank_omega``, the
rod straight and the slider where the joints put them.
"""

from __future__ import annotations

import math

from .._results import ConfigError
from .params import Param, nonnegative, positive, unit_interval
from .spec import SceneSpec, register

PARAMETERS = {
    "crank_length": positive(0.15, "crank length, pivot to the rod's pin", "m"),
    "crank_mass": positive(0.2, "crank mass (a uniform bar: inertia m l^2 / 12 about its centre)", "kg"),
    "rod_length": positive(0.3, "connecting rod length, pin to pin", "m"),
    "n_elements": Param(4, "number of beam elements of the rod", kind="int", lo=1, hi=1000),
    "E": positive(2.0e11, "Young's modulus of the rod", "Pa"),
    "nu": Param(0.3, "Poisson's ratio of the rod", lo=-1.0, lo_open=True, hi=0.5, hi_open=True),
    "rho": positive(7870.0, "density of the rod", "kg/m^3"),
    "area": positive(2.827e-5, "rod cross-section area A (a 6 mm round bar)", "m^2"),
    "second_moment": positive(6.362e-11, "rod second moment of area I", "m^4"),
    "shear_factor": Param(0.9, "shear area ratio As/A of the rod", lo=0.0, lo_open=True, hi=1.0),
    "slider_mass": positive(0.1, "slider mass", "kg"),
    "stop_x": Param(0.44, "x of the stop the slider strikes from the left (beyond crank_length + rod_length: "
                    "never reached)", "m"),
    "e": unit_interval(0.8, "Newton restitution coefficient at the stop"),
    "drive": Param("free", "free crank, or driven by the constant torque 'torque'", kind="choice",
                   choices=("free", "torque")),
    "torque": Param(0.0, "constant torque on the crank, counter-clockwise (drive = 'torque')", "N m"),
    "crank_angle": Param(-math.pi / 2, "initial crank angle from the +x axis", "rad", lo=-math.pi, hi=math.pi),
    "crank_omega": Param(30.0, "initial crank angular velocity (counter-clockwise)", "rad/s"),
    "gravity": nonnegative(9.81, "gravitational acceleration (along -y)", "m/s^2"),
}

OBSERVABLES = ("crank_angle", "crank_omega", "slider_x", "slider_v", "rod_deflection", "gap", "force",
               "constraint", "constraint_rate", "energy")
UNITS = {"crank_angle": "rad", "crank_omega": "rad/s", "slider_x": "m", "slider_v": "m/s", "rod_deflection": "m",
         "gap": "m", "force": "N", "constraint": "m", "constraint_rate": "m/s", "energy": "J"}


def slider_x(p) -> float:
    """The slider's initial x [m] (rigid mechanism, rod straight)."""
    r, L = p["crank_length"], p["rod_length"]
    return r * math.cos(p["crank_angle"]) + math.sqrt(L**2 - (r * math.sin(p["crank_angle"]))**2)


def check(p):
    if not p["crank_length"] < p["rod_length"]:
        raise ConfigError(f"crank_length ({p['crank_length']} m) must be shorter than rod_length "
                          f"({p['rod_length']} m): the crank could not turn")
    x = slider_x(p)
    if not p["stop_x"] - x > 1e-12 * p["rod_length"]:
        raise ConfigError(f"the slider starts at x = {x:.6g} m, at or beyond the stop (stop_x = {p['stop_x']} m); "
                          "the stop must lie to its right")


def make(p, concrete):
    import jax
    import jax.numpy as jnp

    from .._system import Beam2D, Gravity, Pin, PlaneContact, PointMass, PrescribedForce, RigidBody2D, Slider, System

    r, L, th, om = p["crank_length"], p["rod_length"], p["crank_angle"], p["crank_omega"]
    direction = jnp.stack([jnp.cos(th), jnp.sin(th)])
    tip_velocity = r * om * jnp.stack([-jnp.sin(th), jnp.cos(th)])
    phi = jnp.arcsin(-r * jnp.sin(th) / L)  # rod angle: the slider stays on y = 0
    phi_dot = -r * om * jnp.cos(th) / (L * jnp.cos(phi))
    x_slider = r * jnp.cos(th) + L * jnp.cos(phi)
    v_slider = -r * om * jnp.sin(th) - L * jnp.sin(phi) * phi_dot
    zero = jnp.zeros_like(x_slider)

    system = System(dim=2)
    system.add_body("crank", RigidBody2D(mass=p["crank_mass"], inertia=p["crank_mass"] * r**2 / 12.0,
                                         position=0.5 * r * direction, angle=th, velocity=0.5 * tip_velocity,
                                         angular_velocity=om))
    system.add_body("rod", Beam2D(E=p["E"], nu=p["nu"], rho=p["rho"], area=p["area"],
                                  second_moment=p["second_moment"], length=L, n_elements=concrete["n_elements"],
                                  position=r * direction, angle=phi, velocity=tip_velocity, angular_velocity=phi_dot,
                                  shear_factor=p["shear_factor"]))
    system.add_body("slider", PointMass(p["slider_mass"], position=jnp.stack([x_slider, zero]),
                                        velocity=jnp.stack([v_slider, zero])))
    system.add_joint("pivot", Pin("ground", "crank", at_b=jnp.stack([-0.5 * r, 0.0 * r])))
    system.add_joint("crank_pin", Pin("crank", "rod", at_a=jnp.stack([0.5 * r, 0.0 * r]), node_b=0))
    system.add_joint("slider_pin", Pin("rod", "slider", node_a=-1))
    system.add_joint("guide", Slider("ground", "slider", axis=[1.0, 0.0], fixed_angle=False))
    system.add_contact("stop", PlaneContact("slider", normal=[-1.0, 0.0], origin=jnp.stack([p["stop_x"], zero]),
                                            e=p["e"]))
    system.add_force("gravity", Gravity(jnp.stack([zero, -p["gravity"]])))
    torque = p["torque"] if concrete["drive"] == "torque" else None
    if torque is not None:
        system.add_force("drive", PrescribedForce("crank", direction=[1.0], amplitude=torque, torque=True))
    model, q0, v0 = system.build()

    crank, rod, slider = (model.coordinates(name) for name in ("crank", "rod", "slider"))
    ne = concrete["n_elements"]
    mid_a, mid_b = ne // 2, (ne + 1) // 2  # the rod's middle: a node, or the middle of the central element
    energy = jax.vmap(model.energy)
    bilateral = jax.vmap(model.bilateral)
    bilateral_rate = jax.vmap(lambda q, v: jax.jvp(model.bilateral, (q,), (v,))[1])

    def observables(sol):
        q, v = sol.q, sol.v
        nodes = q[:, rod].reshape(q.shape[0], -1, 3)[:, :, :2]
        chord = nodes[:, -1] - nodes[:, 0]
        chord = chord / jnp.linalg.norm(chord, axis=1, keepdims=True)
        middle = 0.5 * (nodes[:, mid_a] + nodes[:, mid_b]) - nodes[:, 0]
        theta = q[:, crank][:, 2]
        total = energy(q, v)
        if torque is not None:  # the constant torque's potential -τ (θ - θ0)
            total = total - torque * (theta - th)
        return {
            "crank_angle": theta, "crank_omega": v[:, crank][:, 2],
            "slider_x": q[:, slider][:, 0], "slider_v": v[:, slider][:, 0],
            "rod_deflection": chord[:, 0] * middle[:, 1] - chord[:, 1] * middle[:, 0],
            "gap": p["stop_x"] - q[:, slider][:, 0],
            "force": sol.impulse[:, -1] / sol.h,
            "constraint": jnp.max(jnp.abs(bilateral(q)), axis=1),
            "constraint_rate": jnp.max(jnp.abs(bilateral_rate(q, v)), axis=1),
            "energy": total,
        }

    return model, q0, v0, observables


SPEC = register(
    SceneSpec(
        name="slider_crank",
        description="Slider-crank with a flexible connecting rod (planar beam) and a stop the slider strikes",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-4, "t_end": 0.1, "rho_inf": 0.5},
        make=make,
        check=check,
        observables=OBSERVABLES,
        error_observables=("slider_x", "slider_v", "rod_deflection"),
        units=UNITS,
        plotted=("crank_angle", "crank_omega", "slider_x", "slider_v", "rod_deflection", "force", "constraint",
                 "energy"),
    )
)
