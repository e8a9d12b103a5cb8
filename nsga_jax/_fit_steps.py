"""The steps of a bounded fit in scaled variables (each parameter divided by
its starting value): steps projected on the parameters' ranges, a
backtracking Armijo line search, and a compass search where the line search
fails (:func:`~nsga_jax._identify.identify`). Host functions of the compiled
``evaluate(u) -> ((loss, prediction), gradient)`` and ``advance(u, step, alpha)``."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import optax

COMPASS = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6)
"""The changes of one scaled parameter (its starting value is 1), largest
first, that a fit tries where a line search failed (a compass search): the
loss is piecewise smooth through impacts, and a jump on the gradient's path
can end a line search away from a minimum. The first change that lowers the
loss is taken; where none of the smallest does, the fit stands at a local
minimum of the simulated loss at that resolution."""


MAX_STEP = 0.5
"""The largest change of a scaled parameter (its starting value is 1) that
one iteration tries: a longer step is shortened to it. Through impacts the
loss is piecewise smooth, and a full quasi-Newton step can land far away in
a flat region (e = 0: no rebound, no gradient)."""


FIT_LOSS = 1e-6
"""A fit whose loss fell below this fraction of its starting value fits the
data, even where it stops on a bound with a zero gradient."""


def flat_bound(active, grad, losses, gtol) -> bool:
    """Stopped on a bound where the whole gradient vanishes without fitting
    the data: a flat region of the loss (e = 0 for a bouncing ball), no fit."""
    return bool(active) and float(optax.tree.norm(grad)) < gtol and losses[-1] > FIT_LOSS * losses[0]


def at_bounds(u, bounds) -> dict[str, str]:
    """The parameters on a bound of their range: ``{name: "lower" | "upper"}``."""
    out = {}
    for k, (lo, hi) in bounds.items():
        x = float(u[k])
        tol = 1e-12 * max(1.0, abs(x))
        if x <= lo + tol:
            out[k] = "lower"
        elif x >= hi - tol:
            out[k] = "upper"
    return out


def projected_gradient(grad, active):
    """The gradient with the components that push out of the range zeroed
    (a bound the loss pushes into is where a bounded minimum lies)."""
    def keep(k, g):
        side = active.get(k)
        return jnp.where((side == "lower" and g > 0) or (side == "upper" and g < 0), 0.0, g) if side else g

    return {k: keep(k, g) for k, g in grad.items()}


def free_step(step, active):
    """The step with the components that would leave the range through an
    active bound zeroed (the projected direction)."""
    def keep(k, d):
        side = active.get(k)
        return jnp.where((side == "lower" and d < 0) or (side == "upper" and d > 0), 0.0, d) if side else d

    return {k: keep(k, d) for k, d in step.items()}


def bounded_step(step, largest: float):
    """``step`` shortened so that no component exceeds ``largest``."""
    size = max(float(jnp.max(jnp.abs(d))) for d in step.values())
    return step if size <= largest else {k: d * (largest / size) for k, d in step.items()}


def line_search(evaluate, advance, u, value, grad, step, trials: int = 30, c1: float = 1e-4):
    """Backtracking from the full step: the first trial with sufficient decrease
    (Armijo), else the trial with the lowest loss if it is below ``value``
    (the loss is piecewise smooth through impacts: a jump can hide the
    decrease that the gradient promises); ``None`` when no trial decreases.
    Returns ``((u, value, prediction, gradient) or None, evaluations)``."""
    slope = float(optax.tree.vdot(grad, step))
    if not slope < 0.0:  # not a descent direction: steepest descent, same length
        scale = float(optax.tree.norm(step)) / max(float(optax.tree.norm(grad)), 1e-300)
        step = jax.tree.map(lambda g: -scale * g, grad)
        slope = -scale * float(optax.tree.vdot(grad, grad))
    best = None
    for trial in range(trials):
        alpha = 0.5**trial
        candidate = advance(u, step, alpha)
        (c_value, c_pred), c_grad = evaluate(candidate)
        c_value = float(c_value)
        if not math.isfinite(c_value):
            continue
        if c_value <= value + c1 * alpha * slope:
            return (candidate, c_value, c_pred, c_grad), trial + 1
        if c_value < value and (best is None or c_value < best[1]):
            best = (candidate, c_value, c_pred, c_grad)
    return best, trials


def compass_search(evaluate, advance, u, value, names):
    """A compass search where a line search failed: each parameter moved by
    ±δ for δ in :data:`COMPASS`, largest first (projected on its range).
    Returns ``((u, value, prediction, gradient) of the first move that lowers
    the loss, or None; evaluations; whether a smallest move left the loss
    unchanged, a flat loss)``."""
    evaluations, flat = 0, False
    for delta in COMPASS:
        for k in names:
            for sign in (1.0, -1.0):
                step = {n: jnp.asarray(sign * delta if n == k else 0.0) for n in names}
                candidate = advance(u, step, 1.0)
                if all(float(candidate[n]) == float(u[n]) for n in names):  # against a bound
                    continue
                (c_value, c_pred), c_grad = evaluate(candidate)
                evaluations += 1
                c_value = float(c_value)
                if c_value < value:
                    return (candidate, c_value, c_pred, c_grad), evaluations, False
                flat |= delta == COMPASS[-1] and abs(c_value - value) <= 1e-14 * abs(value)
    return None, evaluations, flat


def scaled_bounds(spec, scale: float) -> tuple[float, float]:
    """A parameter's range in scaled variables; open bounds are kept 1e-6 inside."""
    lo = spec.lo + (1e-6 * abs(scale) if spec.lo_open else 0.0)
    hi = spec.hi - (1e-6 * abs(scale) if spec.hi_open else 0.0)
    return tuple(sorted((lo / scale, hi / scale)))


def to_values(u, scale) -> dict[str, float]:
    """Scaled variables back to parameter values."""
    return {k: float(u[k]) * scale[k] for k in u}


__all__ = ["COMPASS", "FIT_LOSS", "MAX_STEP", "at_bounds", "bounded_step", "compass_search", "flat_bound", "free_step",
           "line_search", "projected_gradient", "scaled_bounds", "to_values"]
