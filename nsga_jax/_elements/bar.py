"""Two-node linear bar (axial displacements), small strain.

Element parameters ``p = (EA, le, rhoA)``: axial stiffness [N], element length
[m], mass per unit length [kg/m]. Coordinates are the two nodal axial
displacements u_e (2,) [m].
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def bar_internal_force(u_e: jax.Array, v_e: jax.Array, p) -> jax.Array:
    """Internal force on the two nodes, shape (2,) [N]: N = EA (u2 - u1)/le pulls
    node 1 forward and node 2 back."""
    EA, le, _ = p
    normal = EA * (u_e[1] - u_e[0]) / le
    return jnp.stack([normal, -normal])


def bar_consistent_mass(p) -> jax.Array:
    """Consistent mass matrix rhoA le / 6 [[2, 1], [1, 2]], shape (2, 2) [kg]."""
    _, le, rhoA = p
    return rhoA * le / 6.0 * jnp.array([[2.0, 1.0], [1.0, 2.0]], jnp.result_type(rhoA, le))


def bar_lumped_mass(p) -> jax.Array:
    """Lumped (row-sum) mass matrix rhoA le / 2 I, shape (2, 2) [kg]."""
    _, le, rhoA = p
    return rhoA * le / 2.0 * jnp.eye(2, dtype=jnp.result_type(rhoA, le))
