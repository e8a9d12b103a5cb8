"""A system's iteration matrices as element blocks and its contact rows
node by node, for large flexible models solved without assembling
(:attr:`~nsga_jax._models.Model.matrix_free`, :mod:`~nsga_jax._integrators.krylov`).

A system is matrix-free when its bodies are flexible bodies of one kind that
give element blocks and node coordinates (:class:`~nsga_jax.system.HexSolid` s,
or :class:`~nsga_jax.system.Bar` s), with forces that do not depend on the
state (gravity), joints that pin nodes to the ground
(:class:`~nsga_jax.system.Pin` between ``ground`` and a node: a clamped face
is one pin a node), and only :class:`~nsga_jax.system.PlaneContact` s on
their nodes (with or without friction), no node in two contacts or pins:
each contact row is then the plane's unit normal on one node's coordinates,
a pin's rows ± the coordinate axes on its node's, and the rows are
orthonormal. Friction's tangent rows (the plane's tangents on the same
node) are spelled out as an array where the law needs them
(:func:`~nsga_jax._integrators.contact_rows.dense_rows`). Several bodies are one matrix
whose element blocks are the bodies' blocks on their coordinates (block
diagonal: nothing couples them but the contacts' rows). Derived from the
parts, never declared.
"""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp
import numpy as np

from .._assembly import StaticIndex
from .._blocks import ElementMatrix, NodeRows
from .._custom_types import Vector
from . import layout
from .base import GROUND
from .contacts import PlaneContact, node_indices
from .joints import Pin


def _offsets(model) -> list[int]:
    """Where each body's coordinates start in the system's (static)."""
    slices = layout.body_slices(model)
    return [slices[name].start for name in model.body_names]


def _flexible(model, name: str) -> Any:
    """The body ``name``: a flexible body with ``node_dofs`` (checked by :func:`is_matrix_free`)."""
    return layout.body(model, name)


def _body_coordinates(model, q: Vector) -> list[Vector]:
    """Each body's slice of q (one body: q itself, no slice in the program)."""
    if len(model.bodies) == 1:
        return [q]
    slices = layout.body_slices(model)
    return [q[slices[name]] for name in model.body_names]


def _contact_dofs(model) -> list[np.ndarray]:
    """Each contact's nodes as the system's coordinates, shape (k, w) each (static)."""
    slices = layout.body_slices(model)
    out = []
    for contact in model.contacts:
        body = _flexible(model, contact.body)
        out.append(slices[contact.body].start + body.node_dofs(node_indices(body, contact.nodes)))
    return out


def _pinned_node(joint) -> tuple[str, int, float] | None:
    """(body, node, sign of its rows) of a pin holding a node to the ground, else ``None`` (static)."""
    if type(joint) is not Pin:
        return None
    if joint.body_a == GROUND and joint.node_b is not None and joint.body_b != GROUND:
        return joint.body_b, joint.node_b, -1.0  # g = x_a - x_b
    if joint.body_b == GROUND and joint.node_a is not None and joint.body_a != GROUND:
        return joint.body_a, joint.node_a, 1.0
    return None


def _pin_dofs(model) -> list[tuple[np.ndarray, float]]:
    """Each pin's node as the system's coordinates, shape (1, w), and its rows' sign (static)."""
    slices = layout.body_slices(model)
    out = []
    for joint in model.joints:
        name, node, sign = _pinned_node(joint)  # type: ignore[misc]
        out.append((slices[name].start + _flexible(model, name).node_dofs((node,)), sign))
    return out


def is_matrix_free(model) -> bool:
    """Whether the system's matrices can be left as element blocks and its rows node by node (static)."""
    if not model.bodies or any(body.n_bilateral for body in model.bodies):
        return False
    if any(_pinned_node(joint) is None for joint in model.joints):
        return False
    if len({type(body) for body in model.bodies}) != 1:  # one kind: one element block size and node width
        return False
    if not all(hasattr(body, "element_stiffness") and hasattr(body, "node_dofs") for body in model.bodies):
        return False
    if not model.constant_mass or model.velocity_dependent_force:
        return False
    if any(f.depends_on_state(layout.bodies_of(model, f)) for f in model.forces):
        return False
    if any(not isinstance(c, PlaneContact) or c.nodes is None for c in model.contacts):
        return False
    dofs = [tuple(row) for group in _contact_dofs(model) for row in group]
    dofs += [tuple(node[0]) for node, _ in _pin_dofs(model)]
    return len(set(dofs)) == len(dofs)


def _stacked(model, blocks: list[ElementMatrix]) -> ElementMatrix:
    """The bodies' element blocks as one matrix on the system's coordinates."""
    if len(blocks) == 1:
        return blocks[0]
    dofs = np.concatenate([offset + b.dofs.array for offset, b in zip(_offsets(model), blocks)])
    return ElementMatrix(jnp.concatenate([b.blocks for b in blocks]), StaticIndex(dofs), model.n_dof,
                         blocks[0].width)


def element_mass(model, q: Vector) -> ElementMatrix:
    """M of the system, element by element."""
    return _stacked(model, [body.element_mass(qb) for body, qb in zip(model.bodies, _body_coordinates(model, q))])


def kronecker_mass(model):
    """The system's M as a Kronecker product where it has one (one box solid), else ``None``."""
    body = model.bodies[0]
    return body.kronecker_mass() if len(model.bodies) == 1 and hasattr(body, "kronecker_mass") else None


def element_stiffness(model, q: Vector) -> ElementMatrix:
    """K(q) of the system (gravity adds none), element by element."""
    return _stacked(model, [body.element_stiffness(qb)
                            for body, qb in zip(model.bodies, _body_coordinates(model, q))])


def constraint_rows(model, q: Vector) -> NodeRows:
    """The constraints' rows, shape (nc, n): each pin's ± coordinate axes on its
    node's coordinates (the bilateral rows, first), then each plane's unit
    normal on its nodes' coordinates."""
    cols, vals = [], []
    for dofs, sign in _pin_dofs(model):
        width = dofs.shape[1]
        cols.append(np.repeat(dofs, width, axis=0))
        vals.append(sign * jnp.eye(width, dtype=q.dtype))
    for contact, dofs in zip(model.contacts, _contact_dofs(model)):
        cols.append(dofs)
        normal = (contact.normal / jnp.linalg.norm(contact.normal)).astype(q.dtype)
        vals.append(jnp.broadcast_to(normal, (len(dofs), normal.shape[0])))
    width = model.bodies[0].dim
    if not cols:
        return NodeRows(jnp.zeros((0, width), q.dtype), StaticIndex(np.zeros((0, width))), model.n_dof)
    return NodeRows(jnp.concatenate(vals), StaticIndex(np.concatenate(cols)), model.n_dof)
