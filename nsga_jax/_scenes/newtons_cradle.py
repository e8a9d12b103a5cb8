"""Scene ``newtons_cradle``: N equal balls on a frictionless line, the first
thrown at the others, built as a :class:`~nsga_jax.system.System`.

Coordinates: the ball centres x_1 … x_N [m] along the line (1D point
masses), at rest ``2 radius + gap`` apart; ball 1 moves toward the others at
``velocity``. Neighbours meet through :class:`~nsga_jax.system.SphereContact`
(gap ``x_{i+1} - x_i - 2 radius >= 0``, Newton restitution e). With every
gap > 0 and resolved by the step, each impact is a binary exchange: for
e = 1 the last ball leaves with the first one's velocity and the others
stop. The exact solution is that sequence of binary collisions
(:func:`nsga_jax._exact.newtons_cradle`).
"""

from __future__ import annotations

from .._exact import newtons_cradle
from .params import Param, positive, unit_interval
from .spec import SceneSpec, register

MAX_BALLS = 10
"""The most balls a cradle has (its observables are named for each ball)."""

PARAMETERS = {
    "n_balls": Param(5, "number of balls N", kind="int", lo=2, hi=MAX_BALLS),
    "mass": positive(0.1, "mass of each ball", "kg"),
    "radius": positive(0.01, "radius of each ball", "m"),
    "gap": positive(1e-3, "gap between neighbours at rest (> 0: binary impacts; resolve it by the step, "
                    "h * velocity < gap)", "m"),
    "velocity": Param(1.0, "initial velocity of ball 1 toward the others", "m/s", lo=0.0),
    "e": unit_interval(1.0, "Newton restitution coefficient between neighbours"),
}


def _positions(p, n: int):
    """The centres at rest (N,) [m]: ball i (from 0) at i (2 radius + gap)."""
    import jax.numpy as jnp

    return jnp.arange(n) * (2.0 * p["radius"] + p["gap"])


def make(p, concrete):
    import jax.numpy as jnp

    from .._system import PointMass, SphereContact, System

    n = concrete["n_balls"]
    x0 = _positions(p, n)
    system = System(dim=1)
    for i in range(n):
        velocity = p["velocity"] if i == 0 else 0.0
        system.add_body(f"ball{i + 1}", PointMass(p["mass"], x0[i:i + 1], jnp.reshape(velocity, (1,))))
    for i in range(1, n):
        system.add_contact(f"contact{i}", SphereContact(f"ball{i}", f"ball{i + 1}", p["radius"], p["radius"],
                                                        p["e"]))
    model, q0, v0 = system.build()

    def observables(sol):
        x, v = sol.q, sol.v
        out = {f"x{i + 1}": x[:, i] for i in range(n)}
        out.update({f"v{i + 1}": v[:, i] for i in range(n)})
        out.update({f"gap{i}": x[:, i] - x[:, i - 1] - 2.0 * p["radius"] for i in range(1, n)})
        out["momentum"] = p["mass"] * jnp.sum(v, axis=1)
        out["energy"] = 0.5 * p["mass"] * jnp.sum(v**2, axis=1)
        return out

    return model, q0, v0, observables


def exact(p):
    import numpy as np

    n = p["n_balls"]
    x0 = np.arange(n) * (2.0 * p["radius"] + p["gap"])
    v0 = np.zeros(n)
    v0[0] = p["velocity"]

    def solution(ts):
        x, v = newtons_cradle(ts, x0, v0, p["mass"], p["radius"], p["e"])
        out = {f"x{i + 1}": x[:, i] for i in range(n)}
        out.update({f"v{i + 1}": v[:, i] for i in range(n)})
        out.update({f"gap{i}": x[:, i] - x[:, i - 1] - 2.0 * p["radius"] for i in range(1, n)})
        out["momentum"] = p["mass"] * v.sum(axis=1)
        out["energy"] = 0.5 * p["mass"] * (v**2).sum(axis=1)
        return out

    return solution


_BALLS = range(1, MAX_BALLS + 1)
OBSERVABLES = (*(f"v{i}" for i in _BALLS), *(f"x{i}" for i in _BALLS), *(f"gap{i}" for i in _BALLS[:-1]),
               "momentum", "energy")

SPEC = register(
    SceneSpec(
        name="newtons_cradle",
        description="Newton's cradle: N equal balls on a frictionless line, the first thrown at the others",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-4, "t_end": 0.01},
        make=make,
        exact=exact,
        observables=OBSERVABLES,
        error_observables=("x1", "v1", "x2", "v2"),
        units={**{k: "m/s" for k in OBSERVABLES if k.startswith("v")},
               **{k: "m" for k in OBSERVABLES if k.startswith(("x", "gap"))}, "momentum": "kg m/s", "energy": "J"},
        plotted=("v1", "v2", "v3", "v4", "v5", "gap1", "momentum", "energy"),
    )
)
