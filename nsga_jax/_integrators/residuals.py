"""What the sub-problems' residuals share: the multiplier scalings, the
augmented-Lagrangian residual of the projections (eqs. 37 and 42) and the
round-off floors added to the convergence test (eq. 51).

Multipliers inside the sub-problems are scaled as in the paper (ks λ̃, kp ν,
kv Λ are the physical values); records are physical: λ̃ [N], ν [N s²] and the
impulse Λ [N s] (Λ/h is the mean contact force over the step).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Scalar, ScalarLike, Vector
from .._models.base import Model
from .newton import Residual, convergence_bound

ROUNDOFF_FACTOR = 64.0
"""The residual floor is ``ROUNDOFF_FACTOR * eps * (||K|| ||q|| + ||C|| ||v||)``
(scaled like the residual), see :mod:`nsga_jax._integrators.newton`."""

DIVERGENCE_FACTOR = 1e10
"""A coupled iteration whose residual grows this many times beyond its start has diverged."""


class Scaling(eqx.Module):
    """Multiplier scalings and penalties (after eq. 50): ks = ps = m̄/h, kp = pp = kv = pv = m̄."""

    ks: Scalar
    kp: Scalar
    kv: Scalar

    @classmethod
    def of(cls, model: Model, h: Scalar) -> "Scaling":
        mbar = jnp.asarray(model.mbar)  # in the model's precision (a Python number: weakly typed)
        return cls(ks=mbar / h, kp=mbar, kv=mbar)


def roundoff_floor(scale: Scalar, K_norm, C_norm, q, v, inertia: ScalarLike = 0.0) -> Scalar:
    """``ROUNDOFF_FACTOR * eps * scale * (||K|| ||q|| + ||C|| ||v|| + inertia)``: the
    round-off of a residual whose terms cancel; ``inertia`` adds the round-off of
    an inertia term formed from a difference of velocities (step 1's v̇̃)."""
    eps = jnp.finfo(q.dtype).eps
    return ROUNDOFF_FACTOR * eps * scale * (K_norm * jnp.linalg.norm(q) + C_norm * jnp.linalg.norm(v) + inertia)


def constraint_floor(k: Scalar, G: jax.Array, x: Vector) -> Scalar:
    """``ROUNDOFF_FACTOR * eps * k * || |G| |x| ||``: the round-off of the scaled
    constraint rows ``k g_q v`` (x = v) or ``k g(q)`` (x = q, for gaps about as
    large as ``|g_q| |q|``) at their solution, where the rows' exact values are
    zero; row by row, so that one contact's round-off never excuses another's
    violation. Negligible in float64 against eq. 51's bound; in float32 it is
    what lets a converged projection pass the test."""
    eps = jnp.finfo(x.dtype).eps
    return ROUNDOFF_FACTOR * eps * k * jnp.linalg.norm(abs(G) @ jnp.abs(x))


def augmented_residual(inertia, force, G, c, mu, k, p, candidates, unilateral, tol_r, tol_f) -> Residual:
    """Residual of a projection sub-problem (eqs. 37 and 42).

    With the augmented multiplier ``aug = k mu - p c`` and the active set
    ``candidates ∩ (bilateral ∪ {aug >= 0})``:
    ``[inertia - force - G^T aug_active;  -k c (active);  -(k²/p) mu (inactive)]``.
    Returns the :class:`Residual` with ``aux = (active, aug)``.
    """
    aug = k * mu - p * c
    active = candidates & (~unilateral | (aug >= 0))
    reaction = G.T @ jnp.where(active, aug, 0.0)
    r2 = jnp.where(active, -k * c, -(k**2 / p) * mu)
    r = jnp.concatenate([inertia - force - reaction, r2])
    return Residual(r, convergence_bound([inertia, force, reaction, r2], tol_r, tol_f), (active, aug))
