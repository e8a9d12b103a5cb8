"""Scene ``flexible_pendulum``: the paper's §4.3, a geometrically exact beam
pendulum falling from the horizontal onto a wall."""

from __future__ import annotations

import math

from .._results import ConfigError
from .params import Param, positive, unit_interval
from .spec import SceneSpec, register

PARAMETERS = {
    "length": positive(1.0, "beam length", "m"),
    "n_elements": Param(8, "number of beam elements", kind="int", lo=1, hi=10_000),
    "area": positive(1e-4, "cross-section area A", "m^2"),
    "inertia": positive(8.33e-10, "second moment of area I", "m^4"),
    "shear_factor": Param(5.0 / 6.0, "shear area ratio As/A", lo=0.0, lo_open=True, hi=1.0),
    "E": positive(2.1e11, "Young's modulus", "Pa"),
    "nu": Param(0.3, "Poisson's ratio", lo=-1.0, lo_open=True, hi=0.5, hi_open=True),
    "rho": positive(7800.0, "density", "kg/m^3"),
    "gravity": Param(9.81, "gravitational acceleration (along -y)", "m/s^2", lo=0.0),
    "angle": Param(0.0, "initial (unstressed, at rest) angle of the beam from the +x axis", "rad",
                   lo=-math.pi, hi=math.pi),
    "wall_x": Param(math.sqrt(2.0) / 2.0,
                    "x of the vertical wall facing the tip; admissible side: where the tip starts", "m"),
    "e": unit_interval(0.0, "Newton restitution coefficient at the wall"),
    "mass_matrix": Param("consistent", "mass matrix", kind="choice", choices=("consistent", "lumped")),
}


def _offset(p) -> float:
    return p["length"] * math.cos(p["angle"]) - p["wall_x"]


def check(p):
    if abs(_offset(p)) <= 1e-12 * p["length"]:
        raise ConfigError("the tip starts on the wall: the admissible side is undefined; move the wall")


def make(p, concrete):
    """The pendulum as a system: a :class:`~nsga_jax.system.Beam2D` pinned to the
    ground at its root (the origin), gravity along -y, and the wall's line
    x = ``wall_x`` facing the tip node from the side where the tip starts."""
    import jax
    import jax.numpy as jnp

    from .._system import Beam2D, Gravity, Pin, PlaneContact, System

    side = math.copysign(1.0, _offset(concrete))
    system = System(dim=2)
    system.add_body("beam", Beam2D(E=p["E"], nu=p["nu"], rho=p["rho"], area=p["area"], second_moment=p["inertia"],
                                   length=p["length"], n_elements=concrete["n_elements"], position=jnp.zeros(2),
                                   angle=p["angle"], shear_factor=p["shear_factor"],
                                   lumped=concrete["mass_matrix"] == "lumped"))
    system.add_joint("pivot", Pin("beam", "ground", node_a=0, at_b=jnp.zeros(2)))
    system.add_contact("wall", PlaneContact("beam", normal=[side, 0.0],
                                            origin=jnp.stack([jnp.asarray(p["wall_x"], float), jnp.zeros(())]),
                                            e=p["e"], nodes=[-1]))
    g = jnp.asarray(p["gravity"], float)
    system.add_force("gravity", Gravity(jnp.stack([jnp.zeros_like(g), -g])))
    model = system.model()  # the scene's check has refused an initial penetration
    q0, v0 = model.initial_state()
    energy = jax.vmap(model.energy)

    def observables(sol):
        q, v = sol.q, sol.v
        return {
            "tip_x": q[:, -3], "tip_y": q[:, -2], "tip_theta": q[:, -1],
            "tip_vx": v[:, -3], "tip_vy": v[:, -2], "tip_omega": v[:, -1],
            "tip_uy": q[:, -2] - q0[-2],
            "gap": side * (q[:, -3] - p["wall_x"]),
            "force": sol.impulse[:, -1] / sol.h,
            "energy": energy(q, v),
        }

    return model, q0, v0, observables


SPEC = register(
    SceneSpec(
        name="flexible_pendulum",
        description="Geometrically exact beam pendulum (8 elements) hitting a wall, paper §4.3",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-4, "t_end": 0.35},
        make=make,
        check=check,
        observables=("tip_x", "tip_y", "tip_theta", "tip_vx", "tip_vy", "tip_omega", "tip_uy", "gap", "force",
                     "energy"),
        error_observables=("tip_uy", "tip_vy"),
        units={"tip_x": "m", "tip_y": "m", "tip_theta": "rad", "tip_vx": "m/s", "tip_vy": "m/s",
               "tip_omega": "rad/s", "tip_uy": "m", "gap": "m", "force": "N", "energy": "J"},
        plotted=("tip_x", "tip_vx", "tip_uy", "tip_vy", "gap", "force", "tip_omega", "energy"),
    )
)
