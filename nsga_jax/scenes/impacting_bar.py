"""Scene ``impacting_bar``: the paper's §4.2, an elastic bar hitting a rigid wall."""

from __future__ import annotations

import numpy as np

from ..models.bar import ElasticBar
from ..results import ConfigError
from .base import Scene, SceneSpec, register
from .params import Param, positive, unit_interval

PARAMETERS = {
    "E": positive(900.0, "Young's modulus", "Pa"),
    "rho": positive(1.0, "density", "kg/m^3"),
    "area": positive(1.0, "cross-section area", "m^2"),
    "length": positive(10.0, "bar length", "m"),
    "n_elements": Param(200, "number of two-node elements", kind="int", lo=1, hi=100_000),
    "gap": Param(5.005, "initial distance d0 between the tip and the wall", "m", lo=0.0,
                 note="a negative gap is an initial penetration of the wall"),
    "velocity": Param(10.0, "initial uniform velocity v0, positive toward the wall", "m/s"),
    "e": unit_interval(0.0, "Newton restitution coefficient at the wall"),
    "mass_matrix": Param("consistent", "mass matrix", kind="choice", choices=("consistent", "lumped")),
}

NODE_045_FROM_TIP = 0.45  # m, the paper's Fig. 5(a)/6(b) observation point


def build(p, solver) -> Scene:
    ne = p["n_elements"]
    le = p["length"] / ne
    node045 = ne - int(round(NODE_045_FROM_TIP / le))
    if not 0 <= node045 <= ne:
        raise ConfigError(f"the bar (length {p['length']} m) is shorter than {NODE_045_FROM_TIP} m")
    model = ElasticBar(E=p["E"], rho=p["rho"], area=p["area"], length=p["length"], gap0=p["gap"],
                       e=p["e"], n_elements=ne, lumped=p["mass_matrix"] == "lumped")
    q0 = np.zeros(ne + 1)
    v0 = np.full(ne + 1, p["velocity"])

    zeros = np.zeros(ne + 1)
    M = np.asarray(model.mass(zeros))
    K = np.asarray(model.tangents(zeros, zeros, 0.0)[0])

    def observe(sol):
        energy = 0.5 * np.einsum("ti,ij,tj->t", sol.v, M, sol.v) + 0.5 * np.einsum("ti,ij,tj->t", sol.q, K, sol.q)
        return {
            "tip_u": sol.q[:, -1],
            "tip_v": sol.v[:, -1],
            "node045_u": sol.q[:, node045],
            "node045_v": sol.v[:, node045],
            "tip_gap": p["gap"] - sol.q[:, -1],
            "tip_force": sol.impulse[:, 0] / sol.h,
            "energy": energy,
        }

    return Scene("impacting_bar", model, q0, v0, p, solver, observe)


SPEC = register(
    SceneSpec(
        name="impacting_bar",
        description="Elastic bar (200 linear elements) hitting a rigid wall, paper §4.2",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-3, "t_end": 1.5},
        build=build,
        observables=("tip_u", "tip_v", "node045_u", "node045_v", "tip_gap", "tip_force", "energy"),
        error_observables=("node045_u", "node045_v", "tip_u", "tip_v"),
    )
)
