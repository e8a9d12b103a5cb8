"""Scene ``impacting_bar``: the paper's §4.2, an elastic bar hitting a rigid wall."""

from __future__ import annotations

from .._results import ConfigError
from .params import Param, positive, unit_interval
from .spec import SceneSpec, register

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


def _node045(concrete) -> int:
    return concrete["n_elements"] - int(round(NODE_045_FROM_TIP * concrete["n_elements"] / concrete["length"]))


def check(p):
    if not 0 <= _node045(p) <= p["n_elements"]:
        raise ConfigError(f"the bar (length {p['length']} m) is shorter than {NODE_045_FROM_TIP} m")


def make(p, concrete):
    """The bar as a system: a :class:`~nsga_jax.system.Bar` from x = -length to
    its tip at x = 0, moving at ``velocity``, and the wall at x = ``gap``
    facing the tip node. Coordinates: the nodal displacements u."""
    import jax
    import jax.numpy as jnp

    from .._system import Bar, PlaneContact, System

    ne = concrete["n_elements"]
    node045 = _node045(concrete)
    system = System(dim=1)
    system.add_body("bar", Bar(E=p["E"], rho=p["rho"], area=p["area"], length=p["length"], n_elements=ne,
                               position=-jnp.asarray(p["length"], float), velocity=p["velocity"],
                               lumped=concrete["mass_matrix"] == "lumped"))
    system.add_contact("wall", PlaneContact("bar", normal=[-1.0], origin=jnp.reshape(p["gap"], (1,)), e=p["e"],
                                            nodes=[-1]))
    model = system.model()  # the scene's check has refused an initial penetration
    q0, v0 = model.initial_state()

    def observables(sol):
        energy = jax.vmap(model.energy)(sol.q, sol.v)  # ½ vᵀMv + ½ uᵀKu, element by element
        return {
            "tip_u": sol.q[:, -1],
            "tip_v": sol.v[:, -1],
            "node045_u": sol.q[:, node045],
            "node045_v": sol.v[:, node045],
            "tip_gap": p["gap"] - sol.q[:, -1],
            "tip_force": sol.impulse[:, 0] / sol.h,
            "energy": energy,
        }

    return model, q0, v0, observables


SPEC = register(
    SceneSpec(
        name="impacting_bar",
        description="Elastic bar (200 linear elements) hitting a rigid wall, paper §4.2",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-3, "t_end": 1.5},
        make=make,
        check=check,
        observables=("tip_u", "tip_v", "node045_u", "node045_v", "tip_gap", "tip_force", "energy"),
        error_observables=("node045_u", "node045_v", "tip_u", "tip_v"),
        units={"tip_u": "m", "tip_v": "m/s", "node045_u": "m", "node045_v": "m/s", "tip_gap": "m",
               "tip_force": "N", "energy": "J"},
    )
)
