"""Accuracy measures: the paper's eq. 52 error and observed orders of convergence."""

from __future__ import annotations

import numpy as np


def relative_l1_error(numerical, reference) -> float:
    """Eq. 52: ``sum_n |f_n - f(t_n)| / sum_n |f(t_n)|`` over a common time grid."""
    numerical = np.asarray(numerical, dtype=float)
    reference = np.asarray(reference, dtype=float)
    if numerical.shape != reference.shape:
        raise ValueError(f"shapes differ: {numerical.shape} vs {reference.shape}")
    denom = np.abs(reference).sum()
    if denom == 0.0:
        raise ValueError("the reference is identically zero; eq. 52 is undefined")
    return float(np.abs(numerical - reference).sum() / denom)


def l1_errors(numerical, reference) -> tuple[float | None, float]:
    """``(eq. 52's relative error, or None where the reference is identically
    zero and eq. 52 is undefined; the largest absolute error max_n |f_n - f(t_n)|
    in the observable's unit)``: a sticking block's exact displacement is 0."""
    numerical = np.asarray(numerical, dtype=float)
    reference = np.asarray(reference, dtype=float)
    absolute = float(np.max(np.abs(numerical - reference))) if numerical.size else 0.0
    if numerical.shape == reference.shape and not np.abs(reference).sum():
        return None, absolute
    return relative_l1_error(numerical, reference), absolute


def observed_order(step_sizes, errors) -> float:
    """Slope of the least-squares line through (log h, log error)."""
    h = np.log(np.asarray(step_sizes, dtype=float))
    e = np.log(np.asarray(errors, dtype=float))
    return float(np.polyfit(h, e, 1)[0])
