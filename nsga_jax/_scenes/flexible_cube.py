"""Scene ``flexible_cube``: the paper's §4.4, a soft hex8 cube bouncing on a floor."""

from __future__ import annotations

from .._results import ConfigError
from .friction_forces import friction_force
from .params import Param, contact_mu, friction_coefficient, positive, unit_interval
from .spec import SceneSpec, register

PARAMETERS = {
    "side": positive(0.1, "side of the cube", "m"),
    "divisions": Param(5, "elements along each side", kind="int", lo=1, hi=40),
    "E": positive(90.0, "Young's modulus", "Pa"),
    "nu": Param(0.3, "Poisson's ratio", lo=-1.0, lo_open=True, hi=0.5, hi_open=True),
    "rho": positive(1.0, "density", "kg/m^3"),
    "gravity": Param(9.81, "gravitational acceleration (along -z)", "m/s^2", lo=0.0),
    "x0": Param(0.0, "initial x of the centroid", "m"),
    "y0": Param(0.0, "initial y of the centroid", "m"),
    "height": Param(0.35, "initial height of the centroid above the floor", "m",
                    note="the bottom face must start on or above the floor: height >= side/2"),
    "velocity": Param(0.0, "initial vertical velocity (upward positive)", "m/s"),
    "vx": Param(0.0, "initial horizontal velocity, x", "m/s"),
    "vy": Param(0.0, "initial horizontal velocity, y", "m/s"),
    "e": unit_interval(0.0, "Newton restitution coefficient at every bottom node"),
    "mu": friction_coefficient(0.0, "at every bottom node"),
}


def check(p):
    if p["height"] < p["side"] / 2:
        raise ConfigError(f"initial penetration: height {p['height']} m is below side/2 = {p['side'] / 2} m")


def make(p, concrete):
    """The cube as a system: a :class:`~nsga_jax.system.HexSolid` centred at
    height ``height`` above the floor z = 0 moving at (vx, vy, velocity),
    gravity along -z, and its bottom face's nodes against the floor (with
    Coulomb friction where ``mu > 0``)."""
    import jax
    import jax.numpy as jnp

    from .._system import Gravity, HexSolid, PlaneContact, System

    n = concrete["divisions"]
    height, g = jnp.asarray(p["height"], float), jnp.asarray(p["gravity"], float)
    zero = jnp.zeros_like(height)
    cube = HexSolid(size=jnp.stack([p["side"]] * 3), divisions=(n, n, n), E=p["E"], nu=p["nu"], rho=p["rho"],
                    position=jnp.stack([jnp.asarray(p["x0"], float), jnp.asarray(p["y0"], float), height]),
                    velocity=jnp.stack([jnp.asarray(p[k], float) for k in ("vx", "vy", "velocity")]))
    corner, top = cube.node(0, 0, 0), cube.node(0, 0, -1)  # x1: the bottom corner at (-a/2, -a/2); x8 above it
    system = System(dim=3)
    system.add_body("cube", cube)
    system.add_contact("floor", PlaneContact("cube", normal=[0.0, 0.0, 1.0], origin=[0.0, 0.0, 0.0], e=p["e"],
                                             nodes="bottom", mu=contact_mu(p, concrete)))
    system.add_force("gravity", Gravity(jnp.stack([zero, zero, -g])))
    model = system.model()  # the scene's check has refused an initial penetration
    q0, v0 = model.initial_state()
    energy = jax.jit(jax.vmap(model.energy))

    def observables(sol):
        out = {
            "x1_ux": sol.q[:, 3 * corner] - q0[3 * corner],
            "x1_vx": sol.v[:, 3 * corner],
            "x1_uz": sol.q[:, 3 * corner + 2] - q0[3 * corner + 2],
            "x1_vz": sol.v[:, 3 * corner + 2],
            "x8_uz": sol.q[:, 3 * top + 2] - q0[3 * top + 2],
            "x8_vz": sol.v[:, 3 * top + 2],
            "min_gap": sol.gap.min(axis=1),
            "contact_force": sol.impulse.sum(axis=1) / sol.h,
            "energy": energy(sol.q, sol.v),
            "gaps": sol.gap,
        }
        if concrete["mu"] > 0:
            force = friction_force(sol, [0.0, 0.0, 1.0])
            out["friction_x"], out["friction_y"] = force[:, 0], force[:, 1]
        return out

    return model, q0, v0, observables


SPEC = register(
    SceneSpec(
        name="flexible_cube",
        description="Soft hex8 cube (125 elements, St Venant-Kirchhoff) bouncing on a floor, paper §4.4",
        parameters=PARAMETERS,
        solver_defaults={"h": 3e-5, "t_end": 0.3},
        make=make,
        check=check,
        observables=("x1_uz", "x1_vz", "x8_uz", "x8_vz", "min_gap", "contact_force", "energy", "gaps",
                     "x1_ux", "x1_vx", "friction_x", "friction_y"),
        error_observables=("x1_uz", "x1_vz"),
        units={"x1_uz": "m", "x1_vz": "m/s", "x8_uz": "m", "x8_vz": "m/s", "min_gap": "m",
               "contact_force": "N", "energy": "J", "gaps": "m",
               "x1_ux": "m", "x1_vx": "m/s", "friction_x": "N", "friction_y": "N"},
        plotted=("x1_uz", "x1_vz", "x8_uz", "x8_vz", "min_gap", "contact_force", "energy"),
    )
)
