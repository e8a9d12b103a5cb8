"""Planar geometrically exact (Reissner) beam element, two nodes, shear deformable.

Element coordinates ``x_e = [x1, y1, θ1, x2, y2, θ2]`` (absolute positions [m]
and cross-section rotations [rad]); parameters ``p = (EA, GAs, EI, L0,
rhoA, rhoI, theta0)``: axial, shear and bending stiffness, reference length,
mass and rotary inertia per unit length, and the reference orientation of the
(straight) element. Strains at the midpoint (one-point reduced integration, the
remedy against shear locking of linear elements):

    ε = x' cos θ + y' sin θ - 1,   γ = -x' sin θ + y' cos θ,   κ = θ' - 0,

with ``(·)'`` the derivative with respect to the reference arc length. Any rigid
motion (translation, rotation of the whole element by any angle) gives zero
strain exactly, so zero internal force.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def beam_strains(x_e: jax.Array, p) -> jax.Array:
    """(ε, γ, κ) at the element midpoint."""
    _, _, _, L0, _, _, _ = p
    dx = (x_e[3] - x_e[0]) / L0
    dy = (x_e[4] - x_e[1]) / L0
    theta = 0.5 * (x_e[2] + x_e[5])
    c, s = jnp.cos(theta), jnp.sin(theta)
    return jnp.stack([dx * c + dy * s - 1.0, -dx * s + dy * c, (x_e[5] - x_e[2]) / L0])


def beam_energy(x_e: jax.Array, p) -> jax.Array:
    """Strain energy of the element [J]."""
    EA, GAs, EI, L0, _, _, _ = p
    eps, gam, kap = beam_strains(x_e, p)
    return 0.5 * L0 * (EA * eps**2 + GAs * gam**2 + EI * kap**2)


def beam_internal_force(x_e: jax.Array, v_e: jax.Array, p) -> jax.Array:
    """Internal force (6,) = -dU/dx_e [N, N, N m]."""
    return -jax.grad(beam_energy)(x_e, p)


def beam_mass(p, lumped: bool = False) -> jax.Array:
    """Mass matrix (6, 6): translational ρA and rotary ρI inertia, consistent
    (L0/6 [[2, 1], [1, 2]]) or lumped (L0/2 I) for each of x, y, θ."""
    _, _, _, L0, rhoA, rhoI, _ = p
    real = jnp.result_type(L0, rhoA, rhoI)  # the element's precision
    base = (L0 / 2.0 * jnp.eye(2, dtype=real) if lumped
            else L0 / 6.0 * jnp.array([[2.0, 1.0], [1.0, 2.0]], real))
    per_dof = jnp.stack([rhoA, rhoA, rhoI])
    # dof order: node a, component i -> 3 a + i
    return jnp.einsum("ab,i,ij->aibj", base, per_dof, jnp.eye(3, dtype=real)).reshape(6, 6)
