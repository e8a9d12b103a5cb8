"""The rows and unknowns of the velocity-level and position-level
sub-problems, with and without Coulomb friction
(:mod:`~nsga_jax._integrators.friction`): whether a model has friction, how
many multipliers a sub-problem has, Newton's start, and the rows whose rates
the law constrains (g_q and, with friction, g_T below them).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._blocks import NodeRows
from .._custom_types import Vector
from .._models.base import Model


def has_friction(model: Model) -> bool:
    """Whether the model has frictional contacts (static)."""
    return model.n_friction > 0


def multiplier_count(model: Model) -> int:
    """Unknown multipliers of a velocity-level sub-problem: nc normal ones and,
    with friction, nf · d tangential ones."""
    return model.n_constraints + model.n_friction * model.friction_dim


def projection_start(model: Model, q: Vector):
    """Newton's starting point of the position correction and of a
    velocity-level sub-problem: U = 0, ν = 0 (or W = 0, Λ = 0), the
    multipliers with their tangential part where the model has friction."""
    return (jnp.zeros_like(q), jnp.zeros((multiplier_count(model),), q.dtype))


def dense_rows(G: jax.Array | NodeRows) -> jax.Array:
    """G as an (m, n) array: friction's Delassus matrix G A⁻¹ Gᵀ is formed
    (module docstring), so a matrix-free model's node rows are spelled out
    for it, O(m n) numbers, never n × n."""
    return G.dense() if isinstance(G, NodeRows) else G


def velocity_rows(model: Model, q: Vector, G: jax.Array) -> jax.Array:
    """The rows whose rates the velocity sub-problem constrains: g_q (nc, n) and,
    with friction, g_T (nf · d, n) below them (G: an array or, read as one,
    a matrix-free model's :class:`~nsga_jax._blocks.NodeRows`)."""
    if not has_friction(model):
        return G
    return jnp.concatenate([dense_rows(G), model.tangent_jacobian(q)])
