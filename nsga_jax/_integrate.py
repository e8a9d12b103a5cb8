"""The pure entry point: ``integrate(model, scheme, t0, t1, h, q0, v0)`` -> :class:`Solution`.

One JAX function of the model, the scheme's settings and the initial state:
``jit``, ``vmap``, sharding, ``jax.grad``, ``jax.jacfwd`` and ``jax.jvp`` all
apply. :func:`~nsga_jax.simulate` is the host driver over the same step
(progress, chunks written to disk, named errors, float32 runs, monitors) and
returns the same :class:`Solution` type.

- Each Newton sub-problem is differentiated implicitly (implicit function
  theorem at the converged solution, active set frozen), never by unrolling
  its iterations: a custom JVP of :func:`nsga_jax._integrators.newton.solve`
  that a run nobody differentiates never evaluates. ``adjoint=`` chooses
  which derivative each step carries (:mod:`nsga_jax._adjoint`).
- The step loop is a ``lax.scan`` over chunks of steps with ``jax.checkpoint``
  on each chunk: reverse mode stores one state per chunk and recomputes a
  chunk during the backward pass, keeping that chunk's per-step residuals,
  so its memory grows like N/c states plus c steps' residuals (c =
  ``checkpoint_every``, √N by default) plus what the loop outputs. Pass
  ``saveat=SaveAt(fn=...)`` to output only what a loss needs.
- A step's residuals are vectors when the iteration matrices are constant
  (linear models), but include dense factorisations (3 n² numbers) when they
  are refactored each step; for those, when c steps of them would exceed
  256 MiB, each step is checkpointed too (recomputed once more in the
  backward pass: 1.7× the gradient's time on the cube, for memory that no longer
  grows with c). ``checkpoint_steps`` overrides the choice.
"""

from __future__ import annotations

import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ._adjoint import ADJOINT_KINDS, AbstractAdjoint, DiscreteAdjoint, refuse_without_implicit_adjoint
from ._first_step import LIMIT_SECONDS, check_first_step
from ._integrators.base import AbstractScheme
from ._integrators.records import StepOutput, output_template
from ._memory import check_fits
from ._models.base import Model
from ._precision import precision_notes, refuse_mixed_precision, require_x64_for_inputs
from ._results import RESULTS, ConfigError, from_code
from ._run_core import advance, constraints_at, prepare_and_init
from ._run_inputs import check_scheme, check_scheme_for_model
from ._saveat import HOST_ONLY, SaveAt, refuse
from ._solution import Solution, first_failed_code, traced_stats
from ._validation import check_model_fields, describe, integer, require_instance, time_grid

MAX_SCAN_STEPS = 2**31 - 1
"""The most steps of one pure run (its scan counts steps in int32; every
step's record is kept until ``SaveAt`` picks the rows, so longer runs would
not fit in memory anyway)."""
STEP_RESIDUALS_BYTES = 2**28  # per chunk: above this, each step is checkpointed as well


# ------------------------------------------------------------ the step count


def _is_traced(x: Any) -> bool:
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(x))


def _step_count(t0, t1, h, n_steps: int | None) -> int:
    """``n_steps`` checked, or N = floor((t1 - t0)/h) from concrete times
    (:func:`~nsga_jax._validation.time_grid`); traced times need ``n_steps``."""
    traced = [name for name, x in (("t0", t0), ("t1", t1), ("h", h)) if _is_traced(x)]
    if n_steps is None:
        if traced:
            raise ConfigError(f"n_steps must be given when {', '.join(traced)} "
                              f"{'is' if len(traced) == 1 else 'are'} traced (under jit, grad or vmap): the "
                              "number of steps is static, floor((t1 - t0)/h) cannot be computed from traced "
                              "times; pass n_steps=N")
        *_, n = time_grid(t0, t1, h)
        return integer("n_steps", n, 1, MAX_SCAN_STEPS)
    n_steps = integer("n_steps", n_steps, 1, MAX_SCAN_STEPS)
    if not traced:
        t0f, t1f, hf, n = time_grid(t0, t1, h)
        if n != n_steps:
            raise ConfigError(f"n_steps = {n_steps} disagrees with floor((t1 - t0)/h) = {n} for t0={t0f}, "
                              f"t1={t1f}, h={hf}; pass n_steps=None or matching times")
    return n_steps


def _initial_record(model: Model, subproblems: tuple[str, ...], t0, q0, v0, dtype) -> StepOutput:
    """The row of t0: the initial state, its gaps and bilateral values, zero
    multipliers, iterations and result."""
    zeros = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), output_template(model, dtype, subproblems))
    return eqx.tree_at(lambda r: (r.t, r.q, r.v, r.gap, r.bilateral), zeros, (t0, q0, v0, *constraints_at(model, q0)))


def integrate(
    model: Model,
    scheme: AbstractScheme,
    t0,
    t1,
    h,
    q0,
    v0,
    *,
    n_steps: int | None = None,
    saveat: SaveAt = SaveAt(),
    adjoint: AbstractAdjoint = DiscreteAdjoint(),
    throw: bool = True,
    checkpoint_every: int | None = None,
    checkpoint_steps: bool | None = None,
    first_step_limit: float | None = LIMIT_SECONDS,
) -> Solution:
    """Integrate ``model`` from t0 to t1 [s] with step h [s] by ``scheme``, as one pure JAX function.

    Args:
        model, scheme: as for :func:`~nsga_jax.simulate` (DS, DSn or MJ; CS
            has no implicit adjoint here).
        t0, t1, h: start and end time and step size [s]; may be traced (no
            recompilation when they change), then ``n_steps`` is needed.
        q0, v0: initial coordinates and velocities (n,).
        n_steps: number of steps N (static); default floor((t1 - t0)/h) from
            concrete times (:func:`~nsga_jax._validation.step_count`). Step k
            starts at t0 + k h (never accumulated).
        saveat: what to keep (:class:`~nsga_jax.SaveAt`): every k-th row, or
            a function of each row's state and record. ``SaveAt.chunks``
            needs the host driver and is refused here.
        adjoint: which derivative the steps carry (:mod:`nsga_jax._adjoint`):
            :class:`~nsga_jax.DiscreteAdjoint` (default), the exact derivative
            of the time-stepping map (impacts held at their steps), or
            :class:`~nsga_jax.ImpactTimeAdjoint`, at each step where a contact
            closes the derivative of a continuous-time rebuild of the step,
            which sees the impact instant move (:mod:`nsga_jax._impact_time`).
            Values are the same with both.
        throw: raise at run time (``eqx.error_if``) if any step fails; with
            ``False`` failures are in ``result``, ``stats["failed_steps"]``
            and (full records) ``records.result``.
        checkpoint_every: steps per checkpointed chunk (default ⌈√N⌉).
        checkpoint_steps: checkpoint each step inside a chunk as well (see
            above; default: only where a chunk's dense residuals would pass
            256 MiB).
        first_step_limit: refuse, before tracing the steps, a run on the
            dense path whose first step is estimated above this many seconds
            (60 by default; :func:`~nsga_jax._first_step.check_first_step`; one
            run: a ``vmap``'s members are not seen); ``None`` runs anyway.

    Returns:
        A :class:`~nsga_jax.Solution` with JAX leaves: ``ts`` (rows,), ``q``,
        ``v`` (rows, n), ``records`` (the stacked records of the kept rows, the
        initial row first, or what ``saveat.fn`` returned for them),
        ``result`` (the first failure's code), ``stats`` (over every step:
        :func:`~nsga_jax._solution.traced_stats`), ``h``.
    """
    check_scheme(scheme)
    refuse(saveat, HOST_ONLY, "integrate (pure)", "nsga_jax.simulate, the host driver")
    n_steps = _step_count(t0, t1, h, n_steps)
    if checkpoint_every is not None:
        integer("checkpoint_every", checkpoint_every, 1)
    require_instance("adjoint", adjoint, AbstractAdjoint, ADJOINT_KINDS)
    require_instance("model", model, Model, "a model instance (a subclass of nsga_jax.Model)")
    check_model_fields(model)  # concrete fields only: traced ones are checked where they were made
    check_scheme_for_model(scheme, model)
    for name, x in (("q0", q0), ("v0", v0)):
        if isinstance(x, (str, bytes)) or x is None:
            raise TypeError(f"{name} must be an array of {model.n_dof} numbers, got {describe(x)}")
        if np.shape(x) != (model.n_dof,):  # numpy's shape: lists too, and tracers by their .shape
            raise ConfigError(f"{name} must have shape ({model.n_dof},), got {np.shape(x)}")
    refuse_without_implicit_adjoint(scheme)
    require_x64_for_inputs(q0=q0, v0=v0)  # float64 NumPy inputs are not rounded to float32 silently
    dtype = jnp.result_type(*(jnp.asarray(x) for x in (q0, v0)), float)  # the precision of q0 and v0
    refuse_mixed_precision(model, scheme, np.dtype(dtype).name)
    precision_notes(model, np.dtype(dtype).name)  # warned once, at trace time
    check_fits(model, scheme, dtype.itemsize)  # the dense matrices of one run (static sizes; a vmap's are not seen)
    check_first_step(model, scheme, np.dtype(dtype).name, limit=first_step_limit)
    t0 = jnp.asarray(t0, dtype)
    h = jnp.asarray(h, dtype)
    q0 = jnp.asarray(q0, dtype)
    v0 = jnp.asarray(v0, dtype)
    ops, state0 = prepare_and_init(model, scheme, t0, q0, v0, h)

    c = checkpoint_every or max(1, math.ceil(math.sqrt(n_steps)))
    n_chunks = -(-n_steps // c)

    if checkpoint_steps is None:
        refactors = not (model.constant_mass and model.linear_force)
        checkpoint_steps = refactors and c * 3 * model.n_dof**2 * dtype.itemsize > STEP_RESIDUALS_BYTES

    padded = n_chunks * c != n_steps  # the last chunk runs past n_steps: mask those steps
    fn = saveat.fn

    def one_step(carry, k):  # carry: the state and the adjoint's extra
        state, extra = carry
        new, out, extra = advance(model, scheme, ops, state, t0 + k.astype(dtype) * h, h, adjoint=adjoint, extra=extra)
        new_carry = (new, extra)
        if padded:
            new_carry = jax.tree_util.tree_map(lambda a, b: jnp.where(k < n_steps, a, b), new_carry, carry)
        if fn is None:
            return new_carry, out
        watched = (out.newton.iterations, out.result, out.gap, out.bilateral, out.bilateral_rate, out.instants,
                   out.fallback)
        return new_carry, (fn(new, out), watched)

    if checkpoint_steps:
        one_step = jax.checkpoint(one_step)

    @jax.checkpoint
    def chunk(carry, ks):
        return lax.scan(one_step, carry, ks)

    _, outs = lax.scan(chunk, (state0, adjoint.init(model, q0)), jnp.arange(n_chunks * c).reshape(n_chunks, c))
    outs = jax.tree_util.tree_map(lambda x: x.reshape((n_chunks * c,) + x.shape[2:])[:n_steps], outs)
    first = _initial_record(model, scheme.subproblems, t0, q0, v0, dtype)
    if fn is None:
        iterations, result, gap, bilateral, rate, instants, fallback = (
            outs.newton.iterations, outs.result, outs.gap, outs.bilateral, outs.bilateral_rate, outs.instants,
            outs.fallback)
        saved = _prepend(first, outs)
    else:
        saved, (iterations, result, gap, bilateral, rate, instants, fallback) = outs
        saved = _prepend(fn(state0, first), saved)
    kept = np.asarray(saveat.kept_steps(n_steps))
    if saveat.every > 1:
        saved = jax.tree_util.tree_map(lambda x: x[kept], saved)
    if fn is None:
        q, v = saved.q, saved.v
    else:
        q = v = jnp.zeros((0, model.n_dof), dtype)
    ts = t0 + h * jnp.asarray(kept, dtype)
    code = first_failed_code(result)
    if throw:  # the first failed step's member names the failure; simulate names its step and time
        ts = from_code(code).error_if(ts, from_code(code) != RESULTS.successful)
    return Solution(ts=ts, q=q, v=v, records=saved, result=code,
                    stats=traced_stats(scheme.subproblems, iterations, result, gap, bilateral, rate, instants,
                                       fallback), h=h,
                    n_steps=n_steps, n_steps_requested=n_steps)


def _prepend(first, rows):
    """``first`` (one row) stacked before ``rows`` (a leading axis of steps)."""
    return jax.tree_util.tree_map(lambda a, b: jnp.concatenate([jnp.asarray(a, b.dtype)[None], b]), first, rows)
