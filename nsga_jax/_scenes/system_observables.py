"""The observables of a system scene: each body's reference point and
velocity, each contact's gap and force (and, with friction, its friction
force and largest slip speed), each joint's violation, the energy."""

from __future__ import annotations

from collections.abc import Callable

from .._system.base import AbstractBody
from .system_parse import SystemDescription


def _has_angle(cls: type) -> bool:
    return getattr(cls, "angle", None) is not AbstractBody.angle


def observable_units(description: SystemDescription) -> dict[str, str]:
    """The scene's observables and their units: per body the position of its
    reference point (a rigid body's origin, a flexible body's tip node
    ``tip_x``...) and its velocity, its angle and angular velocity where it
    has one; per contact its smallest gap and its force, and with a
    friction coefficient ``mu`` the magnitude of its total friction force
    and the largest slip speed of its points; per joint its violation;
    ``energy`` where every force is conservative."""
    axes = "xyz"[:description.dim]
    out: dict[str, str] = {}
    for entry in description.parts:
        if entry.kind == "bodies":
            prefix = f"{entry.name}.tip_" if getattr(entry.cls, "has_nodes", False) else f"{entry.name}."
            out.update({f"{prefix}{a}": "m" for a in axes})
            if _has_angle(entry.cls):
                out[f"{prefix}theta"] = "rad"
            out.update({f"{prefix}v{a}": "m/s" for a in axes})
            if _has_angle(entry.cls):
                out[f"{prefix}omega"] = "rad/s"
    for entry in description.parts:
        if entry.kind == "contacts":
            out[f"{entry.name}.gap"], out[f"{entry.name}.force"] = "m", "N"
            if "mu" in entry.arrays:
                out[f"{entry.name}.friction"], out[f"{entry.name}.slip"] = "N", "m/s"
    for entry in description.parts:
        if entry.kind == "joints":
            out[f"{entry.name}.violation"] = "m"
    if all(getattr(e.cls, "conservative", True) for e in description.parts if e.kind == "forces"):
        out["energy"] = "J"
    return out


def observables_of(model, names: tuple[str, ...]) -> Callable:
    """``Solution -> {name: (rows,)}`` of :func:`observable_units`' names on ``model``."""
    import jax
    import jax.numpy as jnp

    from .._system.base import point

    def observables(sol):
        q, v = sol.q, sol.v
        out = {}
        for body_name, body in zip(model.body_names, model.bodies):
            cut = model.coordinates(body_name)
            node = -1 if body.has_nodes else None
            prefix = f"{body_name}.tip_" if body.has_nodes else f"{body_name}."

            def place(qb, body=body, node=node):
                x = point(body, qb, jnp.zeros((0,), qb.dtype), node)
                return (jnp.concatenate([x, body.angle(qb, node)[None]]) if body.has_angle else x)

            x, xdot = jax.vmap(lambda qb, vb, place=place: jax.jvp(place, (qb,), (vb,)))(q[:, cut], v[:, cut])
            labels = list("xyz"[:body.dim]) + (["theta"] if body.has_angle else [])
            rates = [f"v{a}" for a in "xyz"[:body.dim]] + (["omega"] if body.has_angle else [])
            for i, (label, rate) in enumerate(zip(labels, rates)):
                out[prefix + label], out[prefix + rate] = x[:, i], xdot[:, i]
        if model.contact_names:
            gaps = jax.vmap(model.unilateral)(q)
            nb = model.n_bilateral
            for name in model.contact_names:
                rows = model.rows("contacts", name)
                out[f"{name}.gap"] = jnp.min(gaps[:, rows.start - nb:rows.stop - nb], axis=1)
                out[f"{name}.force"] = jnp.sum(sol.impulse[:, rows], axis=1) / sol.h
            out.update(_friction_observables(model, sol))
        if model.joint_names:
            g = jax.vmap(model.bilateral)(q)
            for name in model.joint_names:
                out[f"{name}.violation"] = jnp.max(jnp.abs(g[:, model.rows("joints", name)]), axis=1)
        if "energy" in names:
            out["energy"] = jax.vmap(model.energy)(q, v)
        return {k: out[k] for k in names}

    return observables


def _friction_observables(model, sol) -> dict:
    """Per frictional contact: ``.friction``, the magnitude of the sum of its
    points' tangential impulses over h [N], and ``.slip``, the largest slip
    speed |g_T v| of its points [m/s] (at the end of each step)."""
    import jax
    import jax.numpy as jnp

    if not model.n_friction:
        return {}
    d = model.friction_dim
    slip = jax.vmap(lambda q, v: model.tangent_jacobian(q) @ v)(sol.q, sol.v).reshape(len(sol.q), -1, d)
    impulse = sol.records.friction.reshape(len(sol.q), -1, d)
    out, start = {}, 0
    for contact, name in zip(model.contacts, model.contact_names):
        if not contact.frictional:
            continue
        span = model.rows("contacts", name)
        stop = start + span.stop - span.start
        out[f"{name}.friction"] = jnp.linalg.norm(jnp.sum(impulse[:, start:stop], axis=1), axis=-1) / sol.h
        out[f"{name}.slip"] = jnp.max(jnp.linalg.norm(slip[:, start:stop], axis=-1), axis=1)
        start = stop
    return out


__all__ = ["observable_units", "observables_of"]
