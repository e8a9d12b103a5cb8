"""The whole system's vectors and matrices assembled from its parts'
contributions: each group of parts of one kind evaluated on the coordinates
of its bodies (gathered by static slices) and scattered back into the force
vector, the block-diagonal body matrices, the constraints and their Jacobian
(:class:`~nsga_jax._system.model.SystemModel`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from .._custom_types import ConstraintVector, Matrix, Vector
from . import layout
from .forces import Gravity
from .groups import call, gather, scatter_block, scatter_vector, shift

if TYPE_CHECKING:
    from .model import SystemModel


def body_vector(model: SystemModel, fn: Callable, *xs: Vector) -> Vector:
    """Per-body vectors (k,) from ``fn(body, *local xs)``, assembled (n,)."""
    if len(model.bodies) == 1:
        return fn(model.bodies[0], *xs)
    out = jnp.zeros((model.n_dof,), xs[0].dtype)
    for group, stacked in layout.body_groups(model):
        (cols,) = group.columns
        out = scatter_vector(out, cols, call(group, fn, stacked, *(gather(x, cols) for x in xs)))
    return out


def body_matrix(model: SystemModel, fn: Callable, *xs: Vector) -> Matrix:
    """Per-body matrices (k, k) from ``fn(body, *local xs)``, assembled block diagonal (n, n)."""
    if len(model.bodies) == 1:
        return fn(model.bodies[0], *xs)
    out = jnp.zeros((model.n_dof, model.n_dof), xs[0].dtype)
    for group, stacked in layout.body_groups(model):
        (cols,) = group.columns
        out = scatter_block(out, cols, cols, call(group, fn, stacked, *(gather(x, cols) for x in xs)))
    return out


def force_parts(model: SystemModel) -> list:
    """Gravity parts alone (evaluated body group by body group), then the
    other forces in groups of one kind."""
    gravity = [f for f in model.forces if isinstance(f, Gravity)]
    others = tuple(f for f in model.forces if not isinstance(f, Gravity))
    return [*gravity, *layout.part_groups(model, others)]


def constraint_vector(model: SystemModel, q: Vector, which: str) -> ConstraintVector:
    """The ``which`` constraints (``"bilateral"``, ``"unilateral"`` or
    ``"all"``, :func:`~nsga_jax._system.layout.row_groups`), assembled."""
    offset = model.n_bilateral if which == "unilateral" else 0
    size = {"bilateral": model.n_bilateral, "unilateral": model.n_unilateral}.get(which, model.n_constraints)
    g = jnp.zeros((size,), q.dtype)
    for group, module, bodies, fn, _ in layout.row_groups(model, which):
        rows = shift(group.rows, -offset)
        (qs,) = layout.slot_coordinates(model, group, q)
        g = scatter_vector(g, rows, call(group, fn, module, bodies, qs))  # rows disjoint, g from zeros
    return g


def jacobian_rows(model: SystemModel, q: Vector, bilateral_only: bool) -> Matrix:
    """The constraint Jacobian g_q, shape (rows, n): the bilateral rows, or
    every row, each group's blocks by ``jax.jacfwd`` on its bodies' coordinates."""
    rows = model.n_bilateral if bilateral_only else model.n_constraints
    G = jnp.zeros((rows, model.n_dof), q.dtype)
    for group, module, bodies, fn, _ in layout.row_groups(model, "bilateral" if bilateral_only else "all"):
        (qs,) = layout.slot_coordinates(model, group, q)
        blocks = call(group, jax.jacfwd(fn, argnums=2), module, bodies, qs)
        for cols, block in zip(group.columns, blocks):
            G = scatter_block(G, group.rows, cols, block)
    return G


def gravity_vector(model: SystemModel, gravity: Gravity, dtype) -> Vector:
    """The generalised force (n,) of a gravity part, body group by body group."""
    f = jnp.zeros((model.n_dof,), dtype)
    for group, stacked in layout.body_groups(model, gravity.bodies):
        (cols,) = group.columns
        f = scatter_vector(f, cols, call(group, lambda b: gravity.on_body(b, dtype), stacked))
    return f
