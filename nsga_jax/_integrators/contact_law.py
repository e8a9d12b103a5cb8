"""The frictionless contact law of the projection sub-problems, as an object.

A sub-problem with constraints is given its contact law as an object with
one interface, :class:`NormalLaw` here or, where the model has frictional
contacts, :class:`~nsga_jax._integrators.friction.FrictionLaw`:

- ``law.residual(inertia, force, G, rate, lam, tol_r, tol_f)``: the
  residual ``[inertia - force - G^T P;  r_c]`` and its ``aux = (active,
  σ, P_T)`` (P_T ``None`` without friction);
- ``law.correction(matrix, r1, r_c, G_up, G_low, lam, rate, bound)``: the
  Newton correction (dx, dΛ) with the coordinates eliminated through
  ``matrix``;
- ``law.damped``: whether the sub-problem's updates are damped
  (:attr:`~nsga_jax._integrators.newton.Problem.line_search`).

:class:`NormalLaw` is the law of eqs. 37 and 42: the augmented multiplier
σ = k Λ - p c (c the gap or the rate of each row), active where a row is
bilateral or σ >= 0 among the candidates, ``G^T σ`` on the active rows
(:func:`~nsga_jax._integrators.residuals.augmented_residual`) and the
bordered correction of the active rows
(:meth:`~nsga_jax._integrators.linalg.AbstractFactorisation.bordered`).

Both laws build Newton's matrix on :func:`linearised_active`, the active set
widened by round-off: a contact whose σ is zero to within round-off (a box
resting on another that the smooth step moved by the same amount: the gap
between them is ±1e-18 m) is linearised as closed whichever sign that
round-off has. The residual and the converged solution keep the law as it
is; the implicit derivative, which solves with Newton's matrix, takes the
closed branch at such a contact (at that kink either branch is valid).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from .._custom_types import Scalar, Vector
from .linalg import AbstractFactorisation
from .newton import Residual
from .residuals import ROUNDOFF_FACTOR, augmented_residual


def linearised_active(aug: jax.Array, candidates: Any, unilateral: jax.Array) -> jax.Array:
    """The rows (bool (nc,)) that Newton's matrix treats as closed: the
    candidates that are bilateral or have σ = k Λ - p c (``aug``, (nc,))
    above -64 eps times the unilateral candidates' largest |σ| (at zero multipliers,
    the round-off of a gap computed among gaps as large as the largest).

    The law is active where σ >= 0, and a contact at the edge of
    complementarity (Λ = 0 and c = 0: the boxes of a stack at rest after
    the smooth step, which moves them all alike) has σ = ±round-off there.
    Its sign then chose Newton's path: with the contact open in the matrix,
    the step that lifts the box below drives the box above into it, and ten
    3D boxes at rest took 41 position iterations at a step, or one, by the
    last bits of the gaps (which OpenBLAS's thread count decided). Closed in
    the matrix, the contact's multiplier is solved with the others and the
    step converges in one iteration. A contact open by more than the band is
    linearised as open. The band must stay at round-off: at √eps of the
    largest |σ| a contact truly open by less than the band was linearised
    closed, pulled to a tensile multiplier, then open again, and a planar
    stack of ten boxes knocked over failed a step in that cycle. The scale
    is the unilateral candidates' alone: a joint's large reaction must not
    widen the band of the contacts. Only the matrix changes: the law's value,
    and so the solution, do not."""
    scale = jnp.max(jnp.where(candidates & unilateral, jnp.abs(aug), 0.0), initial=0.0)
    band = ROUNDOFF_FACTOR * jnp.finfo(aug.dtype).eps * scale
    return candidates & (~unilateral | (aug >= -band))


class NormalLaw(NamedTuple):
    """The frictionless law with scaling ``k`` and penalty ``p`` on the rows
    ``candidates`` (bool (nc,), or ``True`` for every row); ``unilateral``
    (nc,) marks the rows that may open."""

    candidates: Any
    unilateral: jax.Array
    k: Scalar
    p: Scalar

    @property
    def damped(self) -> bool:
        """Whether the Newton updates are damped (:attr:`~nsga_jax._integrators.newton.Problem.line_search`)."""
        return False

    def active(self, lam: jax.Array, rate: jax.Array) -> jax.Array:
        """The active set: candidates that are bilateral or have σ = k Λ - p c >= 0."""
        return self.candidates & (~self.unilateral | (self.k * lam - self.p * rate >= 0))

    def residual(self, inertia: Vector, force: Vector, G: jax.Array, rate: jax.Array, lam: jax.Array,
                 tol_r, tol_f) -> Residual:
        """``[inertia - force - G^T σ_A;  r_c]`` with ``aux = (active, σ, None)``."""
        res = augmented_residual(inertia, force, G, rate, lam, self.k, self.p, self.candidates, self.unilateral,
                                 tol_r, tol_f)
        return res._replace(aux=(*res.aux, None))

    def correction(self, matrix: AbstractFactorisation, r1: Vector, r_c: jax.Array, G_up: jax.Array,
                   G_low: jax.Array, lam: jax.Array, rate: jax.Array, bound: Scalar | None) -> tuple[Vector, jax.Array]:
        """The bordered correction on the rows :func:`linearised_active` at (lam, rate)."""
        active = linearised_active(self.k * lam - self.p * rate, self.candidates, self.unilateral)
        return matrix.bordered(r1, r_c, G_up, G_low, active, self.k, self.p, bound)


__all__ = ["NormalLaw", "linearised_active"]
