"""A system's iteration matrices as element blocks and its contact rows
node by node, for large flexible models solved without assembling
(:attr:`~nsga_jax._models.Model.matrix_free`, :mod:`~nsga_jax._integrators.krylov`).

A system is matrix-free when it is one body that gives element blocks and
node coordinates (a :class:`~nsga_jax.system.HexSolid` or a
:class:`~nsga_jax.system.Bar`), with forces that
do not depend on the state (gravity), no joints, and only frictionless
:class:`~nsga_jax.system.PlaneContact` s on its nodes, no node in two
contacts: each contact row is then the plane's unit normal on one node's
coordinates, and the rows are orthonormal. Derived from the parts, never
declared.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .._assembly import StaticIndex
from .._blocks import ElementMatrix, NodeRows
from .._custom_types import Vector
from . import layout
from .contacts import PlaneContact, node_indices


def _contact_nodes(model) -> list[tuple[int, ...]]:
    body = model.bodies[0]
    return [node_indices(body, c.nodes) for c in model.contacts]


def is_matrix_free(model) -> bool:
    """Whether the system's matrices can be left as element blocks and its rows node by node (static)."""
    if len(model.bodies) != 1 or model.joints or model.n_bilateral:
        return False
    body = model.bodies[0]
    if not (hasattr(body, "element_stiffness") and hasattr(body, "node_dofs")):
        return False
    if not model.constant_mass or model.velocity_dependent_force:
        return False
    if any(f.depends_on_state(layout.bodies_of(model, f)) for f in model.forces):
        return False
    if any(not isinstance(c, PlaneContact) or c.nodes is None or c.frictional for c in model.contacts):
        return False
    nodes = [i % body.n_nodes for group in _contact_nodes(model) for i in group]
    return len(set(nodes)) == len(nodes)


def element_mass(model, q: Vector) -> ElementMatrix:
    """M of the system's one body, element by element."""
    return model.bodies[0].element_mass(q)


def kronecker_mass(model):
    """The system's one body's M as a Kronecker product where it has one (a box solid), else ``None``."""
    body = model.bodies[0]
    return body.kronecker_mass() if hasattr(body, "kronecker_mass") else None


def element_stiffness(model, q: Vector) -> ElementMatrix:
    """K(q) of the system's one body (gravity adds none), element by element."""
    return model.bodies[0].element_stiffness(q)


def constraint_rows(model, q: Vector) -> NodeRows:
    """The contacts' rows: each plane's unit normal on its nodes' coordinates, shape (nc, n)."""
    body = model.bodies[0]
    cols, vals = [], []
    for contact, nodes in zip(model.contacts, _contact_nodes(model)):
        cols.append(body.node_dofs(nodes))
        normal = (contact.normal / jnp.linalg.norm(contact.normal)).astype(q.dtype)
        vals.append(jnp.broadcast_to(normal, (len(nodes), normal.shape[0])))
    width = body.dim
    if not cols:
        return NodeRows(jnp.zeros((0, width), q.dtype), StaticIndex(np.zeros((0, width))), model.n_dof)
    return NodeRows(jnp.concatenate(vals), StaticIndex(np.concatenate(cols)), model.n_dof)
