"""Scene ``rigid_box``: the paper's §4.1, a spinning rigid box bouncing on a floor.

Built as a system: a :class:`~nsga_jax.system.RigidBody3D` in natural
coordinates (12 coordinates, constant mass matrix, 6 quadratic rigidity
constraints), a plane contact of its 8 vertices with the floor z = 0 (with Coulomb
friction of coefficient ``mu`` where ``mu > 0``), and gravity."""

from __future__ import annotations

import numpy as np

from .._results import ConfigError
from .friction_forces import friction_force
from .params import Param, contact_mu, friction_coefficient, positive, unit_interval
from .spec import SceneSpec, register

PARAMETERS = {
    "mass": positive(46.8, "mass of the box", "kg"),
    "lx": positive(0.1, "side along the body x axis", "m"),
    "ly": positive(0.2, "side along the body y axis", "m"),
    "lz": positive(0.3, "side along the body z axis", "m"),
    "x0": Param(0.0, "initial x of the centre of mass", "m"),
    "y0": Param(0.0, "initial y of the centre of mass", "m"),
    "z0": Param(1.0, "initial height of the centre of mass above the floor", "m"),
    "vx0": Param(3.0, "initial velocity of the centre of mass, x", "m/s"),
    "vy0": Param(0.0, "initial velocity of the centre of mass, y", "m/s"),
    "vz0": Param(0.0, "initial velocity of the centre of mass, z (upward positive)", "m/s"),
    "omega_x": Param(60.0, "initial angular velocity, x (body = spatial at t = 0)", "rad/s"),
    "omega_y": Param(60.0, "initial angular velocity, y", "rad/s"),
    "omega_z": Param(0.0, "initial angular velocity, z", "rad/s"),
    "roll": Param(0.0, "initial rotation about x (applied first)", "rad", lo=-np.pi, hi=np.pi),
    "pitch": Param(0.0, "initial rotation about y (applied second)", "rad", lo=-np.pi, hi=np.pi),
    "gravity": Param(9.81, "gravitational acceleration (downward)", "m/s^2", lo=0.0),
    "e": unit_interval(0.8, "Newton restitution coefficient at every vertex"),
    "mu": friction_coefficient(0.0, "at every vertex"),
    "floor": Param("on", "the floor z = 0 exists ('off': free flight)", kind="choice", choices=("on", "off")),
}


def rotation(roll, pitch):
    """R = R_y(pitch) R_x(roll), shape (3, 3)."""
    import jax.numpy as jnp

    cr, sr, cp, sp = jnp.cos(roll), jnp.sin(roll), jnp.cos(pitch), jnp.sin(pitch)
    one, zero = jnp.ones_like(cr), jnp.zeros_like(cr)
    Rx = jnp.array([[one, zero, zero], [zero, cr, -sr], [zero, sr, cr]])
    Ry = jnp.array([[cp, zero, sp], [zero, one, zero], [-sp, zero, cp]])
    return Ry @ Rx


def _sides(p):
    import jax.numpy as jnp

    return jnp.stack([jnp.asarray(p[k], float) for k in ("lx", "ly", "lz")])


def check(p):
    if p["floor"] == "on":
        signs = np.array([[(k >> i) & 1 for i in range(3)] for k in range(8)], float) * 2 - 1
        vertices = 0.5 * signs * np.array([p["lx"], p["ly"], p["lz"]])  # box_vertices, in NumPy
        cr, sr, cp, sp = np.cos(p["roll"]), np.sin(p["roll"]), np.cos(p["pitch"]), np.sin(p["pitch"])
        R0 = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]]) @ np.array(
            [[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])  # rotation(roll, pitch), in NumPy
        lowest = (p["z0"] + vertices @ R0.T[:, 2]).min()
        if lowest < 0.0:
            raise ConfigError(f"initial penetration: the lowest vertex is at z = {lowest:.6g} m; raise z0")


def make(p, concrete):
    import jax.numpy as jnp

    from .._elements.rigid_body import box_inertia, box_vertices
    from .._system import Gravity, PlaneContact, RigidBody3D, System

    sides = _sides(p)
    vertices = box_vertices(sides)
    R0 = rotation(p["roll"], p["pitch"])
    r0 = jnp.stack([jnp.asarray(p[k], float) for k in ("x0", "y0", "z0")])
    omega0 = R0 @ jnp.stack([jnp.asarray(p[k], float) for k in ("omega_x", "omega_y", "omega_z")])
    system = System(dim=3)
    system.add_body("box", RigidBody3D(
        p["mass"], box_inertia(p["mass"], sides), position=r0, rotation=R0,
        velocity=jnp.stack([jnp.asarray(p[k], float) for k in ("vx0", "vy0", "vz0")]), angular_velocity=omega0,
        size=0.5 * jnp.linalg.norm(sides)))
    if concrete["floor"] == "on":
        system.add_contact("floor", PlaneContact("box", normal=[0.0, 0.0, 1.0], origin=[0.0, 0.0, 0.0],
                                                 e=jnp.full(8, p["e"]), points=vertices,
                                                 mu=contact_mu(p, concrete)))
    system.add_force("gravity", Gravity(jnp.stack([jnp.zeros(()), jnp.zeros(()), -jnp.asarray(p["gravity"], float)])))
    model = system.model()  # the scene's parameters and check() rule out an inconsistent initial state
    q0, v0 = model.initial_state()

    def observables(sol):
        box = model.coordinates("box")
        q, v = sol.q[:, box], sol.v[:, box]
        M = model.body("box").mass(q0[box])
        R = jnp.stack([q[:, 3:6], q[:, 6:9], q[:, 9:12]], axis=2)
        Rdot = jnp.stack([v[:, 3:6], v[:, 6:9], v[:, 9:12]], axis=2)
        omega = 0.5 * sum(jnp.cross(R[:, :, i], Rdot[:, :, i]) for i in range(3))
        out = {"x": q[:, 0], "y": q[:, 1], "z": q[:, 2], "vx": v[:, 0], "vy": v[:, 1], "vz": v[:, 2],
               "omega_x": omega[:, 0], "omega_y": omega[:, 1], "omega_z": omega[:, 2]}
        for k in range(8):
            out[f"gap_{k}"] = q[:, 2] + R[:, 2, :] @ vertices[k]
            out[f"gapdot_{k}"] = v[:, 2] + Rdot[:, 2, :] @ vertices[k]
        out["energy"] = 0.5 * jnp.einsum("ti,ij,tj->t", v, M, v) + p["mass"] * p["gravity"] * q[:, 2]
        out["rotation"] = R
        if concrete["floor"] == "on" and concrete["mu"] > 0:
            force = friction_force(sol, [0.0, 0.0, 1.0])
            out["friction_x"], out["friction_y"] = force[:, 0], force[:, 1]
        return out

    return model, q0, v0, observables


SPEC = register(
    SceneSpec(
        name="rigid_box",
        description="Spinning rigid box (natural coordinates) bouncing on a floor, paper §4.1",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-3, "t_end": 0.69},
        make=make,
        check=check,
        observables=("x", "y", "z", "vx", "vy", "vz", "omega_x", "omega_y", "omega_z",
                     *(f"gap_{k}" for k in range(8)), *(f"gapdot_{k}" for k in range(8)), "energy", "rotation",
                     "friction_x", "friction_y"),
        error_observables=("gap_5", "gapdot_5"),  # x_p: the vertex that hits the floor
        units={"x": "m", "y": "m", "z": "m", "vx": "m/s", "vy": "m/s", "vz": "m/s",
               "omega_x": "rad/s", "omega_y": "rad/s", "omega_z": "rad/s",
               **{f"gap_{k}": "m" for k in range(8)}, **{f"gapdot_{k}": "m/s" for k in range(8)},
               "energy": "J", "rotation": "", "friction_x": "N", "friction_y": "N"},
        plotted=("z", "vz", "gap_5", "gapdot_5", "omega_x", "omega_y", "omega_z", "energy"),
    )
)
