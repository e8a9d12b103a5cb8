"""Friction forces of a run, in world coordinates, for the scenes' observables."""

from __future__ import annotations

from typing import Any


def friction_force(sol: Any, normal: Any, first: int = 0, count: int | None = None) -> Any:
    """The total friction force (rows, dim) [N] on the body of the frictional
    plane contacts ``first .. first + count`` (all of them: ``count=None``)
    that share the unit ``normal`` (dim,): the tangential impulses P_T
    (``sol.records.friction``, contact-major, d = dim - 1 per contact) on the
    contacts' tangent basis (:func:`~nsga_jax._system.contacts.tangent_basis`),
    summed over the contacts and divided by the step h."""
    import jax.numpy as jnp

    from .._system.contacts import tangent_basis

    normal = jnp.asarray(normal, float)
    tangents = tangent_basis(normal / jnp.linalg.norm(normal))  # (d, dim)
    d = tangents.shape[0]
    impulses = sol.records.friction
    rows = impulses.shape[0]
    per_contact = jnp.reshape(impulses, (rows, -1, d))
    stop = per_contact.shape[1] if count is None else first + count
    return per_contact[:, first:stop].sum(axis=1) @ tangents.astype(impulses.dtype) / sol.h
