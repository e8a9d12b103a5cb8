"""Scene ``flexible_cube``: the paper's §4.4, a soft hex8 cube bouncing on a floor."""

from __future__ import annotations

import numpy as np

from ..results import ConfigError
from .base import SceneSpec, register
from .params import Param, positive, unit_interval

PARAMETERS = {
    "side": positive(0.1, "side of the cube", "m"),
    "divisions": Param(5, "elements along each side", kind="int", lo=1, hi=40),
    "E": positive(90.0, "Young's modulus", "Pa"),
    "nu": Param(0.3, "Poisson's ratio", lo=-1.0, lo_open=True, hi=0.5, hi_open=True),
    "rho": positive(1.0, "density", "kg/m^3"),
    "gravity": Param(9.81, "gravitational acceleration (along -z)", "m/s^2", lo=0.0),
    "height": Param(0.35, "initial height of the centroid above the floor", "m",
                    note="the bottom face must start on or above the floor: height >= side/2"),
    "velocity": Param(0.0, "initial vertical velocity (upward positive)", "m/s"),
    "e": unit_interval(0.0, "Newton restitution coefficient at every bottom node"),
}


def check(p):
    if p["height"] < p["side"] / 2:
        raise ConfigError(f"initial penetration: height {p['height']} m is below side/2 = {p['side'] / 2} m")


def make(p, concrete):
    import jax
    import jax.numpy as jnp

    from ..assembly import StaticIndex
    from ..elements.hex8 import structured_hex_mesh
    from ..models.solid import HexSolid

    n = concrete["divisions"]
    unit, conn = structured_hex_mesh((1.0, 1.0, 1.0), (n, n, n), (-0.5, -0.5, -0.5))
    bottom = np.nonzero(np.isclose(unit[:, 2], -0.5))[0]
    corner = int(bottom[0])  # node x1: the bottom corner at (-a/2, -a/2)
    top = int(np.nonzero(np.isclose(unit[:, :2], unit[corner, :2]).all(axis=1) & np.isclose(unit[:, 2], 0.5))[0][0])
    nodes = p["side"] * jnp.asarray(unit) + jnp.stack([0.0, 0.0, p["height"]])
    model = HexSolid(
        reference_nodes=nodes, E=p["E"], nu=p["nu"], rho=p["rho"], gravity=p["gravity"], floor_z=0.0,
        e=p["e"], connectivity=StaticIndex(conn), contact_nodes=StaticIndex(bottom),
    )
    q0 = nodes.reshape(-1)
    v0 = jnp.zeros_like(q0).at[2::3].set(p["velocity"])
    energy = jax.jit(jax.vmap(model.energy))

    def observables(sol):
        return {
            "x1_uz": sol.q[:, 3 * corner + 2] - q0[3 * corner + 2],
            "x1_vz": sol.v[:, 3 * corner + 2],
            "x8_uz": sol.q[:, 3 * top + 2] - q0[3 * top + 2],
            "x8_vz": sol.v[:, 3 * top + 2],
            "min_gap": sol.gap.min(axis=1),
            "contact_force": sol.impulse.sum(axis=1) / sol.h,
            "energy": energy(sol.q, sol.v),
            "gaps": sol.gap,
        }

    return model, q0, v0, observables


SPEC = register(
    SceneSpec(
        name="flexible_cube",
        description="Soft hex8 cube (125 elements, St Venant-Kirchhoff) bouncing on a floor, paper §4.4",
        parameters=PARAMETERS,
        solver_defaults={"h": 3e-5, "t_end": 0.3},
        make=make,
        check=check,
        observables=("x1_uz", "x1_vz", "x8_uz", "x8_vz", "min_gap", "contact_force", "energy", "gaps"),
        error_observables=("x1_uz", "x1_vz"),
        units={"x1_uz": "m", "x1_vz": "m/s", "x8_uz": "m", "x8_vz": "m/s", "min_gap": "m",
               "contact_force": "N", "energy": "J", "gaps": "m"},
        plotted=("x1_uz", "x1_vz", "x8_uz", "x8_vz", "min_gap", "contact_force", "energy"),
    )
)
