"""Accuracy measures: the paper's eq. 52 error, observed orders of
convergence, the effective restitution of a run's first impact, and the
energy kept through a run's impacts."""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

if TYPE_CHECKING:
    from ._models.base import Model
    from ._solution import Solution


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


class Rebound(NamedTuple):
    """A contact's first impact in a run, as :func:`first_rebound` measures it."""

    contact: int
    """Which unilateral contact (index among the model's nu)."""
    instant: float
    """The impact's instant [s]: the root of the gap's cubic through the four steps before it."""
    rate_before: float
    """The contact's normal rate g_q v [m/s] at the instant, from the four steps before it."""
    rate_after: float
    """The same from the four steps after it."""

    @property
    def restitution(self) -> float:
        """The effective Newton restitution, -rate_after / rate_before."""
        return -self.rate_after / self.rate_before


def first_rebound(model: Model, sol: Solution) -> Rebound:
    """The first step over which an open contact's normal rate turns from
    closing (below -0.5 m/s, within 1.5 steps of touching) to opening, and
    its rates just before and just after the impact, each extrapolated to
    the impact's instant by cubics through the four saved steps on its side
    (error O(h⁴) for a smooth free flight on either side).

    ``sol``: a run saved at every step (``sol.ts`` equally spaced), with at
    least four steps on either side of the impact."""
    import jax
    import jax.numpy as jnp

    q, v, t = jnp.asarray(sol.q), jnp.asarray(sol.v), np.asarray(sol.ts)
    h = float(t[1] - t[0])
    gaps = np.asarray(jax.vmap(model.unilateral)(q))
    rates = np.asarray(jax.vmap(lambda q, v: model.constraint_jacobian(q)[model.n_bilateral:] @ v)(q, v))
    hits = (rates[1:] > 0.0) & (rates[:-1] < -0.5) & (gaps[:-1] < -1.5 * h * rates[:-1])
    if not hits.any():
        raise ValueError("no impact in the run: no contact's normal rate turns from closing to opening")
    k = int(np.argmax(hits.any(axis=1))) + 1
    i = int(np.argmax(hits[k - 1]))
    before, after = slice(k - 4, k), slice(k + 1, k + 5)
    if k < 4 or k + 5 > len(t):
        raise ValueError(f"the first impact (step {k}) needs four saved steps on either side")
    roots = np.roots(np.polyfit(t[before], gaps[before, i], 3))
    roots = roots[np.isreal(roots)].real
    instant = float(roots[np.argmin(np.abs(roots - t[k - 1]))]) if roots.size else np.nan
    if not t[k - 1] <= instant <= t[k]:
        raise ValueError(f"the first impact's instant ({instant:.6g} s, from the gap's cubic) is outside its step "
                         f"[{t[k - 1]:.6g}, {t[k]:.6g}] s: the steps before it do not resolve the free flight")
    rate_before, rate_after = (float(np.polyval(np.polyfit(t[side], rates[side, i], 3), instant))
                               for side in (before, after))
    return Rebound(i, instant, rate_before, rate_after)


def energy_through_impacts(ts, energy, impacts, delay: float = 1e-3, span: float = 1e-3) -> float:
    """The relative energy change through a run's impacts: the mean of
    ``energy`` [J] over the ``span`` [s] that starts ``delay`` [s] after the
    last step with an impact, over its first value, less 1. A mean, not a
    value: a flexible body set vibrating by the impacts trades kinetic and
    strain energy faster than the steps resolve (the slider-crank's rod).

    ``ts`` (rows,) [s], ``energy`` (rows,) [J], ``impacts`` (rows,) bool: the
    steps with an impulse. ``nan`` where there is no impact or no row in the
    span."""
    ts, energy, impacts = np.asarray(ts), np.asarray(energy), np.asarray(impacts, bool)
    if not impacts.any():
        return float("nan")
    last = ts[impacts][-1]
    after = (ts > last + delay) & (ts <= last + delay + span)
    return float(energy[after].mean() / energy[0] - 1.0) if after.any() else float("nan")
