"""The inputs of a run, checked before anything is traced: the scheme, the
model instance and the initial state. Each refusal names the argument, the
value and what is allowed (:class:`TypeError` for a wrong Python type,
:class:`~nsga_jax.ConfigError` for a bad value); the field checks they use
are :mod:`nsga_jax._validation`'s."""

from __future__ import annotations

import math
import warnings
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._first_step import check_limit
from ._integrators.base import AbstractScheme
from ._models.base import Model
from ._models.redundancy import RedundantConstraintsWarning, bilateral_redundancy, conflict
from ._precision import DTYPES, precision_notes, require_x64_for
from ._results import ConfigError
from ._validation import (
    IMPACT_LAWS,
    WARM_WITH_PERSISTENT,
    check_model_fields,
    choice,
    describe,
    integer,
    real,
    refuse_traced,
    require_instance,
    time_grid,
)


def check_scheme(scheme) -> None:
    """A scheme instance with tolerances in (0, inf), an integer iteration cap
    >= 1, integer sizes >= 0 for DS's fast paths (``krylov_min_dof`` may be
    ``None``), DS's ``impact_law`` one of :data:`~nsga_jax._validation.IMPACT_LAWS`,
    its ``impact_instants`` a bool with ``max_impacts >= 1`` and
    ``0 <= late < min_fraction < 0.5`` and ``0 <= short_fraction < 1``, its ``warm_start`` a bool, and its own
    settings in their ranges (concrete values only: traced settings are
    checked where they were made)."""
    require_instance("scheme", scheme, AbstractScheme, "a scheme instance: nsga_jax.DS(), DSn(), CS() or MJ()")
    integer("max_iter", scheme.max_iter, 1)
    if hasattr(scheme, "reuse_min_dof"):
        integer("reuse_min_dof", scheme.reuse_min_dof, 0)
    if getattr(scheme, "krylov_min_dof", None) is not None:
        integer("krylov_min_dof", scheme.krylov_min_dof, 0)
    if hasattr(scheme, "impact_law"):
        choice("impact_law", scheme.impact_law, IMPACT_LAWS)
    if hasattr(scheme, "impact_instants"):
        if not isinstance(scheme.impact_instants, (bool, np.bool_)):
            raise ConfigError(f"impact_instants must be True or False, got {describe(scheme.impact_instants)}")
        integer("max_impacts", scheme.max_impacts, 1)
        real("min_fraction", scheme.min_fraction, 0.0, 0.5, lo_open=True, hi_open=True)
        real("late", scheme.late, 0.0, scheme.min_fraction, hi_open=True,
             note="a fraction of h, below min_fraction")
        real("short_fraction", scheme.short_fraction, 0.0, 1.0, hi_open=True, note="a fraction of h")
    for flag in ("warm_start", "persistent_contacts"):
        if hasattr(scheme, flag) and not isinstance(getattr(scheme, flag), (bool, np.bool_)):
            raise ConfigError(f"{flag} must be True or False, got {describe(getattr(scheme, flag))}")
    if getattr(scheme, "warm_start", False) and getattr(scheme, "persistent_contacts", False):
        raise ConfigError(WARM_WITH_PERSISTENT)
    settings = {"tol_r": (scheme.tol_r, 0.0, math.inf), "tol_f": (scheme.tol_f, 0.0, math.inf), **scheme.bounds()}
    for name, (value, lo, hi) in settings.items():
        if isinstance(value, jax.core.Tracer):
            continue
        x = float(np.asarray(value))
        if name in ("tol_r", "tol_f"):
            real(name, x, 0.0, lo_open=True)
        elif not (math.isfinite(x) and lo <= x <= hi):
            raise ConfigError(f"{name} must be in [{lo:g}, {hi:g}], got {x}")


def check_scheme_for_model(scheme, model) -> None:
    """What a scheme's options cannot do with this model, refused by name:
    ``DS(persistent_contacts=True)`` on a run that would assemble no matrix
    (:meth:`~nsga_jax.DS.matrix_free`), whose smooth motion carries the
    bilateral rows only."""
    if getattr(scheme, "persistent_contacts", False) and model.n_unilateral and scheme.matrix_free(model):
        raise ConfigError(
            f"persistent_contacts=True runs on assembled matrices; this model ({model.n_dof} coordinates) "
            f"takes the matrix-free path (krylov_min_dof = {scheme.krylov_min_dof}): set krylov_min_dof=None "
            "to run it assembled, or persistent_contacts=False")


def state_vector(name: str, value: Any, n: int) -> np.ndarray:
    """``q0`` or ``v0`` as a float64 vector of shape (n,): numbers only
    (:class:`TypeError` otherwise), finite, of the model's size."""
    if isinstance(value, (str, bytes)) or value is None:
        raise TypeError(f"{name} must be an array of {n} numbers, got {describe(value)}")
    try:
        x = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be an array of {n} numbers, got {describe(value)}") from None
    x = x.reshape(-1) if x.ndim else x.reshape(1)
    if x.shape != (n,):
        raise ConfigError(f"{name} must have shape ({n},), got {np.shape(value)}")
    if not np.all(np.isfinite(x)):
        bad = np.nonzero(~np.isfinite(x))[0]
        raise ConfigError(f"{name} must be finite; non-finite entries at indices {bad.tolist()}")
    return x


def check_initial_state(model, q0: np.ndarray, v0: np.ndarray, tol: float = 1e-9) -> None:
    """Bilateral constraints satisfied and no penetration at t0; bilateral
    constraints that no position satisfies together are refused as such
    (:func:`~nsga_jax._models.redundancy.conflict`)."""
    scale = max(1.0, float(np.abs(q0).max(initial=0.0)))
    if model.n_unilateral:
        gap = np.asarray(model.unilateral(jnp.asarray(q0)))
        if not np.all(np.isfinite(gap)):
            raise ConfigError("the initial gaps are not finite")
        bad = np.nonzero(gap < -tol * scale)[0]
        if bad.size:
            j = int(bad[0])
            raise ConfigError(f"initial penetration: gap {j} is {gap[j]:.6g} m at t0; every gap must be >= 0 "
                              "(move the body out of the obstacle)")
    if model.n_bilateral:
        g = np.asarray(model.bilateral(jnp.asarray(q0)))
        bad = np.nonzero(~(np.abs(g) <= 1e3 * tol * scale))[0]
        contradiction = conflict(model, q0, 1e3 * tol * scale) if bad.size and np.all(np.isfinite(g)) else None
        if contradiction:
            raise ConfigError(contradiction)
        if bad.size:
            j = int(bad[0])
            raise ConfigError(f"the initial position violates bilateral constraint {j} (g = {g[j]:.6g}); "
                              "start from a configuration that satisfies the joints")


def redundancy_notes(model, q0: np.ndarray, stacklevel: int = 3) -> list[str]:
    """The report of redundant bilateral constraints at q0
    (:func:`~nsga_jax._models.redundancy.bilateral_redundancy`), warned
    (:class:`~nsga_jax._models.redundancy.RedundantConstraintsWarning`) before
    the run and returned for its ``warnings``; ``[]`` when there are none."""
    redundancy = bilateral_redundancy(model, q0)
    if redundancy is None:
        return []
    warnings.warn(redundancy.text(), RedundantConstraintsWarning, stacklevel=stacklevel)
    return [redundancy.text()]


def check_model_instance(model) -> None:
    """A model instance whose fields pass :func:`check_model_fields`."""
    require_instance("model", model, Model, "a model instance (a subclass of nsga_jax.Model)")
    check_model_fields(model)


class RunInputs(NamedTuple):
    """A host run's inputs, checked (:func:`check_run_inputs`); one entry of
    ``hs`` and ``n_steps`` per run (one for :func:`~nsga_jax.simulate`, one
    per member for :func:`~nsga_jax.simulate_batch`)."""

    dtype: str
    """``"float64"`` or ``"float32"``."""
    t0: float
    """Start [s]."""
    t1: float
    """End [s]."""
    hs: np.ndarray
    """Step sizes [s], (runs,)."""
    n_steps: np.ndarray
    """Steps of each run, (runs,) int."""
    q0: np.ndarray
    """Initial coordinates, (n,) float64."""
    v0: np.ndarray
    """Initial velocities, (n,) float64."""
    notes: list[str]
    """The redundancy report (:func:`redundancy_notes`) and the precision's
    (:func:`~nsga_jax._precision.precision_notes`), kept in each run's warnings."""


def check_run_inputs(driver: str, model, scheme, t0, t1, q0, v0, *, dtype, observables=None,
                     first_step_limit=None, h=None, hs=None) -> RunInputs:
    """Every check a host run makes before anything is traced, in one place
    for :func:`~nsga_jax.simulate` (one step size ``h``) and
    :func:`~nsga_jax.simulate_batch` (a sequence ``hs``): inputs not traced
    (``driver`` is named in the refusal), the scheme, the model, ``dtype``
    (and JAX's 64-bit mode for float64), the time grid of each step size,
    the initial state (sizes, finite, joints satisfied, contacts not
    penetrated), ``observables`` a function or ``None`` and
    ``first_step_limit`` a number or ``None``. Redundant bilateral
    constraints, and what float32 cannot give the model, are warned about
    once, here. Raises :class:`TypeError` for a
    wrong Python type and :class:`~nsga_jax.ConfigError` for a bad value."""
    steps = {"h": h} if hs is None else {"hs": hs}
    refuse_traced(driver, model=model, scheme=scheme, t0=t0, t1=t1, **steps, q0=q0, v0=v0)
    check_scheme(scheme)
    check_model_instance(model)
    check_scheme_for_model(scheme, model)
    dtype = choice("dtype", dtype, DTYPES)
    require_x64_for(dtype)
    if hs is not None:
        hs = np.atleast_1d(np.asarray(hs, dtype=float)) if not isinstance(hs, (str, bytes)) else hs
        if isinstance(hs, (str, bytes)) or hs.ndim != 1 or hs.size == 0:
            raise TypeError(f"hs must be a non-empty sequence of step sizes, got {describe(hs)}")
    grids = [time_grid(t0, t1, step, dtype) for step in (hs if hs is not None else [h])]
    q0 = state_vector("q0", q0, model.n_dof)
    v0 = state_vector("v0", v0, model.n_dof)
    check_initial_state(model, q0, v0)
    check_limit("first_step_limit", first_step_limit)
    if observables is not None and not callable(observables):
        raise TypeError(f"observables must be a function or None, got {type(observables).__name__}")
    notes = redundancy_notes(model, q0, stacklevel=4)  # at the caller of simulate / simulate_batch
    notes += precision_notes(model, dtype, stacklevel=4)
    return RunInputs(dtype, grids[0][0], grids[0][1], np.array([g[2] for g in grids]),
                     np.array([g[3] for g in grids]), q0, v0, notes)
