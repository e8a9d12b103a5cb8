"""Why a run failed, where the cause predates its first step: the hints a
:class:`~nsga_jax.ConvergenceError` adds to its message."""

from __future__ import annotations

import jax
import numpy as np

from ._integrators.base import StepState
from ._integrators.operators import Operators

FLOAT32_HINT = (
    "The run is in float32 (eps = 1.2e-7): if the residual is within a few hundred eps of the size of "
    "its terms, the limit is the precision; rerun in float64."
)
TERM_NAMES = {"M": "the mass matrix", "K": "the stiffness matrix", "C": "the damping matrix",
              "G": "the constraint Jacobian"}
MATRIX_NAMES = {
    "smooth": "the inverted iteration matrix of the smooth motion sub-problem",
    "position": "the inverted iteration matrix of the position correction",
    "velocity": "the inverted iteration matrix of the velocity jump",
}


def nonfinite_origin(ops: Operators, initial: StepState) -> str:
    """Why a run met a non-finite value, when it was there before the first
    step: a constant operator computed once for the step size (an inverted
    iteration matrix is not finite when the matrix is singular), or the
    initial acceleration (M(q0) singular, or f(q0, v0, t0) or g_q^B(q0) not
    finite; a rank-deficient g_q^B, redundant joints, is no cause: its
    multipliers are the minimum-norm ones).
    Checked on the host only after a failure, so it costs a run nothing.
    Returns ``""`` when both are finite."""

    def finite(tree) -> bool:
        return all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree_util.tree_leaves(tree))

    terms = (ops.mass, ops.force, ops.constraints)
    bad = [name for term in terms for field, name in TERM_NAMES.items()
           if not finite(getattr(term, field, None))]
    bad += [name for sub, name in MATRIX_NAMES.items() if not finite(getattr(ops, sub))]
    causes = []
    if bad:
        listed = bad[0] if len(bad) == 1 else ", ".join(bad[:-1]) + " and " + bad[-1]
        causes.append(f"{listed} (computed once for this h) {'is' if len(bad) == 1 else 'are'} not finite: "
                      "a singular matrix (a coordinate with neither mass nor stiffness?)")
    if not finite(initial.vd):
        causes.append("the initial acceleration is not finite (M(q0) singular, or f(q0, v0, t0) or the "
                      "bilateral Jacobian g_q^B(q0) not finite)")
    return ("Before the first step, " + "; ".join(causes) + ".") if causes else ""
