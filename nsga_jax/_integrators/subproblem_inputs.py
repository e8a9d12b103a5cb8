"""What each sub-problem of a step is given, by name.

A sub-problem builder (:func:`~nsga_jax._integrators.subproblems.smooth_problem`,
:func:`~nsga_jax._integrators.subproblems.position_problem`,
:func:`~nsga_jax._integrators.subproblems.velocity_problem`,
:func:`~nsga_jax._integrators.mj.moreau_jean_problem`) takes one of these
modules and returns its :class:`~nsga_jax._integrators.newton.Problem`;
:func:`~nsga_jax._integrators.newton.solve` differentiates the solution with
respect to the floating-point arrays they hold (the implicit function
theorem), so everything a problem depends on is here, nothing is closed
over. What every sub-problem shares is :class:`StepInputs`: the model, its
operators, the Newton tolerances, the time at the end of the step and the
step size.
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import equinox as eqx
import jax

from .._custom_types import Scalar, ScalarLike, Vector
from .._models.base import Model
from .coefficients import GenAlphaCoefficients
from .model_terms import ForceAt
from .operators import Operators


class NewtonTolerances(NamedTuple):
    """A scheme's Newton settings (``scheme.tolerances``)."""

    tol_r: Scalar
    """Relative tolerance of a residual, against its terms' scale (eq. 51)."""
    tol_f: Scalar
    """Absolute floor of that scale."""
    max_iter: int
    """Iteration cap of one sub-problem."""


class Smooth(NamedTuple):
    """The smooth motion: q̃, ṽ, v̇̃ (n,) and the physical multipliers λ̃ (nb,)."""

    q: Vector
    v: Vector
    vd: Vector
    lam: jax.Array


class StepInputs(eqx.Module):
    """What every sub-problem of a step is given."""

    model: Model
    ops: Operators
    """The model's terms and the iteration matrices (:meth:`AbstractScheme.prepare`)."""
    tol: NewtonTolerances
    t: Scalar
    """Time at the end of the step [s]."""
    h: Scalar
    """Step size [s]."""

    def shared(self) -> dict[str, Any]:
        """These fields by name, to build a sub-problem's inputs from them:
        ``PositionInputs(**step.shared(), smooth=..., ...)``."""
        return {field.name: getattr(self, field.name) for field in dataclasses.fields(StepInputs)}


class SmoothInputs(StepInputs):
    """Step 1, the smooth motion (eqs. 33-34): the predictor and the
    coefficients that make q̃ and v̇̃ affine in ṽ (44b-c)."""

    co: GenAlphaCoefficients
    q_pred: Vector
    """Predicted coordinates (n,)."""
    v_pred: Vector
    """Predicted velocities (n,)."""
    offset: tuple[Vector, Vector] | None = None
    """CS only: the corrections (U, W), so that forces are evaluated at the total motion."""
    held: jax.Array | None = None
    """(nc,) bool, or ``None`` (the paper's smooth motion): the unilateral
    contacts the smooth motion carries as candidate rows
    (``DS(persistent_contacts=True)``, :mod:`~nsga_jax._integrators.persistent_contacts`)."""


class PositionInputs(StepInputs):
    """Step 2, the position correction (eqs. 37-38)."""

    smooth: Smooth
    f_smooth: ForceAt | None
    """The force at the smooth motion (DS), or ``None`` (DSn, CS: no h² f^p term)."""
    with_forces: bool = eqx.field(static=True)
    """Whether the h² f^p term (29) is kept (DS) or dropped (DSn, CS; eq. 31b)."""
    q_prev: Vector | None = None
    """q_n, the start of the step (n,): the slip of frictional contacts is measured from it."""
    left_open: jax.Array | None = None
    """(nc,) bool, or ``None``: rows the correction never activates, the
    contacts a sub-step leaves open up to their located impact instant
    (:mod:`~nsga_jax._integrators.impact_instants`)."""
    pinned: jax.Array | None = None
    """(nc,) bool, or ``None``: contacts the smooth motion held with a pushing
    force, projected here on a zero gap as joints are (their ν of either
    sign: the drift of the smooth motion's velocity-level rows, both ways),
    :mod:`~nsga_jax._integrators.persistent_contacts`."""
    stuck: jax.Array | None = None
    """(nf,) bool, or ``None``: the pinned frictional contacts the smooth
    motion held sticking, projected here on a zero slip over the step."""


class VelocityInputs(StepInputs):
    """Step 3, the velocity jump (eqs. 40-43)."""

    smooth: Smooth
    U: Vector
    """The position correction (n,): the jump is taken at q = q̃ + U."""
    candidates: jax.Array
    """The position correction's active set A (nc,) bool: B ⊆ A."""
    f_smooth: ForceAt | None
    """The force at the smooth motion (DS), or ``None`` (DSn, CS)."""
    G_prev_v_prev: jax.Array
    """g_{q,n} v_n (nc,), the constraint rates at the start of the step (Newton's restitution)."""
    with_forces: bool = eqx.field(static=True)
    """Whether the h f* term (8) is kept (DS) or dropped (DSn, CS; eq. 31a)."""
    pinned: jax.Array | None = None
    """(nc,) bool, or ``None``: as :attr:`PositionInputs.pinned`, on ġ."""
    stuck: jax.Array | None = None
    """(nf,) bool, or ``None``: as :attr:`PositionInputs.stuck`, on the slip velocity."""


class MoreauJeanInputs(StepInputs):
    """The Moreau–Jean step (one problem on v_{n+1} and the impulses)."""

    theta: ScalarLike
    """θ of the θ-method in [0, 1]."""
    q_n: Vector
    v_n: Vector
    f_n: Vector
    """f(q_n, v_n, t_n) (n,)."""
    candidates: jax.Array | None
    """Rows that may take an impulse (nc,) bool: bilaterals, and unilaterals
    closing by mid-step; ``None`` without constraints."""
    restituted: jax.Array | None
    """e g_q(q_n) v_n (nc,), or ``None`` without constraints."""


__all__ = ["MoreauJeanInputs", "NewtonTolerances", "PositionInputs", "Smooth", "SmoothInputs", "StepInputs",
           "VelocityInputs"]
