"""Scene ``box_stack``: a stack of N equal boxes on a floor, at rest or knocked over.

Built as a system of N rigid bodies ``box1`` (on the floor) … ``boxN`` (on
top), planar (:class:`~nsga_jax.system.RigidBody2D`, q = [x, y, θ]) or in
space (:class:`~nsga_jax.system.RigidBody3D`, natural coordinates), each of
width × height (× depth in 3D), centred on the vertical axis and touching
the next one. Every contact carries Coulomb friction ``mu`` and restitution
``e``:

- ``floor{i}``: every corner of box i against the floor (a plane contact);
- ``box{i}_on_box{i-1}``: the bottom corners of box i against the top face
  of box i-1 (a bounded :class:`~nsga_jax.system.FaceContact`, widened by
  1 % of the box so that the coinciding corners of the stack stay on it);
- ``box{i-1}_under_box{i}``: the top corners of box i-1 against the bottom
  face of box i (narrowed by 1 %: it takes over when box i slides or tips
  over an edge of box i-1 and pivots on it).

The stack starts at rest; ``push`` gives the top box a horizontal velocity
that knocks it off. Boxes touch only through these faces and the floor: a
falling box does not collide with the sides of the others.
"""

from __future__ import annotations

from .params import Param, contact_mu, friction_coefficient, positive, unit_interval
from .spec import SceneSpec, register

PARAMETERS = {
    "n_boxes": Param(3, "number of boxes in the stack", kind="int", lo=1, hi=50),
    "dim": Param(2, "space dimension: 2 (planar boxes) or 3", kind="int", lo=2, hi=3),
    "mass": positive(1.0, "mass of each box", "kg"),
    "width": positive(0.2, "side of each box along x", "m"),
    "depth": positive(0.2, "side of each box along y (dim = 3 only)", "m"),
    "height": positive(0.1, "vertical side of each box", "m"),
    "mu": friction_coefficient(0.5, "at every contact"),
    "e": unit_interval(0.0, "Newton restitution coefficient at every contact"),
    "push": Param(0.0, "initial horizontal velocity (along x) of the top box", "m/s"),
    "gravity": positive(9.81, "gravitational acceleration", "m/s^2"),
}

MARGIN = 0.01
"""How much (a fraction of the box's smaller horizontal side) a face is widened or narrowed."""


def box_geometry(dim: int, width, depth, height):
    """``(sides (dim,), corners (2^dim, dim), bottom, top)`` of a box centred
    at its centre of mass: ``bottom`` and ``top`` index its corners."""
    import jax.numpy as jnp

    from .._elements.rigid_body import box_vertices

    if dim == 2:
        sides = jnp.stack([width, height])
        corners = 0.5 * jnp.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]) * sides
        return sides, corners, [0, 1], [2, 3]
    sides = jnp.stack([width, depth, height])
    return sides, box_vertices(sides), [0, 1, 2, 3], [4, 5, 6, 7]


def face_extent(dim: int, sides):
    """Half-sides of a horizontal face along its tangents
    (:func:`~nsga_jax._system.contacts.tangent_basis` of the vertical normal)."""
    import jax.numpy as jnp

    from .._system.contacts import tangent_basis

    up = jnp.eye(dim)[dim - 1]
    return jnp.abs(tangent_basis(up)) @ (0.5 * sides)


def build_system(p, concrete):
    """The stack as a :class:`~nsga_jax.system.System` (p: parameters, traced
    floats; concrete: the validated values for structure)."""
    import jax.numpy as jnp

    from .._elements.rigid_body import box_inertia
    from .._system import FaceContact, Gravity, PlaneContact, RigidBody2D, RigidBody3D, System

    dim, n = concrete["dim"], concrete["n_boxes"]
    m, w, d, hb, g, push = (jnp.asarray(p[k], float) for k in ("mass", "width", "depth", "height", "gravity", "push"))
    sides, corners, bottom, top = box_geometry(dim, w, d, hb)
    up = jnp.eye(dim)[dim - 1]
    mu = contact_mu(p, concrete)
    system = System(dim=dim)
    for i in range(1, n + 1):
        centre = (i - 0.5) * hb * up
        velocity = push * jnp.eye(dim)[0] if i == n else jnp.zeros(dim)
        if dim == 2:
            body = RigidBody2D(m, m * (w**2 + hb**2) / 12.0, position=centre, velocity=velocity)
        else:
            body = RigidBody3D(m, box_inertia(m, sides), position=centre, velocity=velocity,
                               size=0.5 * jnp.linalg.norm(sides))
        system.add_body(f"box{i}", body)
    e = jnp.asarray(p["e"], float)
    for i in range(1, n + 1):
        system.add_contact(f"floor{i}", PlaneContact(f"box{i}", normal=up, origin=jnp.zeros(dim), e=e,
                                                     points=corners, mu=mu))
    half = face_extent(dim, sides)
    margin = MARGIN * jnp.min(half) * 2.0
    for i in range(2, n + 1):
        face = dict(e=e, half_extent=half, depth=0.5 * hb, mu=mu)
        system.add_contact(f"box{i}_on_box{i - 1}", FaceContact(
            f"box{i}", f"box{i - 1}", corners[jnp.array(bottom)], up, 0.5 * hb * up, margin=margin, **face))
        system.add_contact(f"box{i - 1}_under_box{i}", FaceContact(
            f"box{i - 1}", f"box{i}", corners[jnp.array(top)], -up, -0.5 * hb * up, margin=-margin, **face))
    system.add_force("gravity", Gravity(-g * up))
    return system


def make(p, concrete):
    import jax
    import jax.numpy as jnp

    dim, n = concrete["dim"], concrete["n_boxes"]
    model = build_system(p, concrete).model()
    q0, v0 = model.initial_state()
    k = 3 if dim == 2 else 12  # coordinates per box; its centre first
    centres0 = jnp.reshape(q0, (n, k))[:, :dim]

    def observables(sol):
        q = jnp.reshape(sol.q, (-1, n, k))
        v = jnp.reshape(sol.v, (-1, n, k))
        tilt = jnp.abs(q[:, -1, 2]) if dim == 2 else jnp.arccos(jnp.clip(q[:, -1, 11], -1.0, 1.0))
        return {"top_x": q[:, -1, 0], "top_height": q[:, -1, dim - 1], "top_tilt": tilt,
                "drift": jnp.linalg.norm(q[:, :, :dim] - centres0, axis=-1).max(axis=-1),
                "speed": jnp.linalg.norm(v[:, :, :dim], axis=-1).max(axis=-1),
                "energy": jax.vmap(model.energy)(sol.q, sol.v)}

    return model, q0, v0, observables


SPEC = register(
    SceneSpec(
        name="box_stack",
        description="A stack of N boxes on a floor (planar or 3D), friction at every contact: at rest, "
                    "or knocked over by a push of the top box",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-3, "t_end": 1.0},
        make=make,
        observables=("top_x", "top_height", "top_tilt", "drift", "speed", "energy"),
        error_observables=("top_x", "top_height"),
        units={"top_x": "m", "top_height": "m", "top_tilt": "rad", "drift": "m", "speed": "m/s", "energy": "J"},
    )
)
