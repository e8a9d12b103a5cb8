"""A differentiable trajectory: ``trajectory(model, scheme, t0, h, n_steps, q0, v0)``.

Unlike :func:`~nsga_jax.simulate` (a host-driven loop over compiled chunks,
with progress, files and named errors), this is one pure JAX function of the
model, the scheme's settings and the initial state: ``jit``, ``vmap``,
``jax.grad``, ``jax.jacfwd`` and ``jax.jvp`` all apply.

- Each Newton sub-problem is differentiated implicitly (implicit function
  theorem at the converged solution, active set frozen), never by unrolling
  its iterations: a custom JVP of :func:`nsga_jax.integrators.newton.solve`
  that a run nobody differentiates never evaluates. ``adjoint=`` chooses
  which derivative each step carries (:mod:`nsga_jax.adjoint`).
- The step loop is a ``lax.scan`` over chunks of steps with ``jax.checkpoint``
  on each chunk: reverse mode stores one state per chunk and recomputes a
  chunk during the backward pass, keeping that chunk's per-step residuals,
  so its memory grows like N/c states plus c steps' residuals (c =
  ``checkpoint_every``, √N by default) plus what the loop outputs. Pass
  ``observe`` to output only what a loss needs.
- A step's residuals are vectors when the iteration matrices are constant
  (linear models), but include dense factorisations (3 n² numbers) when they
  are refactored each step; for those, when c steps of them would exceed
  256 MiB, each step is checkpointed too (recomputed once more in the
  backward pass: 1.7× the gradient's time on the cube, for memory that no longer
  grows with c). ``checkpoint_steps`` overrides the choice.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax

from ._custom_types import Scalar
from .adjoint import ADJOINT_KINDS, AbstractAdjoint, DiscreteAdjoint, refuse_without_implicit_adjoint
from .integrators.base import AbstractScheme, StepState
from .integrators.records import StepOutput
from .models.base import Model
from .results import RESULTS, ConfigError, from_code
from .validation import check_model_fields, check_scheme, describe, integer, require_instance

MAX_SCAN_STEPS = 2**31 - 1
"""The most steps of one differentiable trajectory (its scan counts steps in int32;
every step's record is kept, so longer runs would not fit in memory anyway)."""
STEP_RESIDUALS_BYTES = 2**28  # per chunk: above this, each step is checkpointed as well


class Trajectory(eqx.Module):
    """Times, states and per-step records of a differentiable run.

    ``ts`` (N+1,); ``q``, ``v`` (N+1, n); ``records``: the stacked
    :class:`~nsga_jax.integrators.records.StepOutput` of the N steps (or what
    ``observe`` returned); ``h`` the step [s]; ``gap0`` the gaps at t0.
    ``impulse`` and ``gap`` have the initial row prepended, like a
    :class:`~nsga_jax.Solution`, so scene observables apply to both.
    """

    ts: jax.Array
    q: jax.Array
    v: jax.Array
    records: Any
    h: Scalar
    gap0: jax.Array

    @property
    def impulse(self) -> jax.Array:
        imp = self.records.impulse
        return jnp.concatenate([jnp.zeros((1,) + imp.shape[1:], imp.dtype), imp])

    @property
    def gap(self) -> jax.Array:
        return jnp.concatenate([self.gap0[None], self.records.gap])

    @property
    def failed(self) -> jax.Array:
        """Whether any step failed (Newton cap or non-finite value)."""
        return jnp.any(from_code(self.records.result) != RESULTS.successful)


def trajectory(
    model: Model,
    scheme: AbstractScheme,
    t0,
    h,
    n_steps: int,
    q0,
    v0,
    *,
    checkpoint_every: int | None = None,
    observe: Callable[[StepState, StepOutput], Any] | None = None,
    throw: bool = True,
    checkpoint_steps: bool | None = None,
    adjoint: AbstractAdjoint = DiscreteAdjoint(),
) -> Trajectory:
    """Integrate ``n_steps`` steps of size ``h`` from (t0, q0, v0), differentiably.

    Args:
        model, scheme: as for :func:`~nsga_jax.simulate` (DS, DSn or MJ; CS
            has no implicit adjoint here).
        t0, h: start time and step size [s] (traced: no recompilation when they change).
        n_steps: number of steps (static).
        q0, v0: initial coordinates and velocities (n,).
        checkpoint_every: steps per checkpointed chunk (default ⌈√N⌉).
        observe: ``(state, record) -> pytree`` evaluated after each step and
            stacked in ``records`` instead of the full record (``q`` and ``v``
            are then not stored either; they are empty).
        throw: raise at run time (``eqx.error_if``) if any step fails; with
            ``False`` failures are only in ``records.result`` (full records) or
            nowhere (``observe``).
        checkpoint_steps: checkpoint each step inside a chunk as well (see
            above; default: only where a chunk's dense residuals would pass
            256 MiB).
        adjoint: which derivative the steps carry (:mod:`nsga_jax.adjoint`):
            :class:`~nsga_jax.DiscreteAdjoint` (default), the exact derivative
            of the time-stepping map (impacts held at their steps), or
            :class:`~nsga_jax.ImpactTimeAdjoint`, at each step where a contact
            closes the derivative of a continuous-time rebuild of the step,
            which sees the impact instant move (:mod:`nsga_jax.impact_time`).
            Values are the same with both.

    Returns:
        A :class:`Trajectory`.
    """
    check_scheme(scheme)
    integer("n_steps", n_steps, 1, MAX_SCAN_STEPS)
    if checkpoint_every is not None:
        integer("checkpoint_every", checkpoint_every, 1)
    require_instance("adjoint", adjoint, AbstractAdjoint, ADJOINT_KINDS)
    require_instance("model", model, Model, "a model instance (a subclass of nsga_jax.Model)")
    check_model_fields(model)  # concrete fields only: traced ones are checked where they were made
    for name, x in (("q0", q0), ("v0", v0)):
        if isinstance(x, (str, bytes)) or x is None:
            raise TypeError(f"{name} must be an array of {model.n_dof} numbers, got {describe(x)}")
        if jnp.shape(x) != (model.n_dof,):
            raise ConfigError(f"{name} must have shape ({model.n_dof},), got {jnp.shape(x)}")
    refuse_without_implicit_adjoint(scheme)
    dtype = jnp.result_type(float)
    t0 = jnp.asarray(t0, dtype)
    h = jnp.asarray(h, dtype)
    q0 = jnp.asarray(q0, dtype)
    v0 = jnp.asarray(v0, dtype)
    ops = scheme.prepare(model, h, t0)
    state0 = scheme.init(model, t0, q0, v0)

    c = checkpoint_every or max(1, math.ceil(math.sqrt(n_steps)))
    n_chunks = -(-n_steps // c)

    if checkpoint_steps is None:
        refactors = not (model.constant_mass and model.linear_force)
        checkpoint_steps = refactors and c * 3 * model.n_dof**2 * dtype.itemsize > STEP_RESIDUALS_BYTES

    padded = n_chunks * c != n_steps  # the last chunk runs past n_steps: mask those steps

    def one_step(carry, k):  # carry: the state and what the adjoint carries (adjoint.init)
        state, extra = carry
        state = eqx.tree_at(lambda s: s.t, state, t0 + k.astype(dtype) * h)  # t0 + k h, never accumulated
        new, out, extra = adjoint.step(scheme, model, ops, state, extra, h)
        new_carry = (new, extra)
        if padded:
            new_carry = jax.tree_util.tree_map(lambda a, b: jnp.where(k < n_steps, a, b), new_carry, carry)
        kept = out if observe is None else (observe(new, out), out.result)
        return new_carry, kept

    if checkpoint_steps:
        one_step = jax.checkpoint(one_step)

    @jax.checkpoint
    def chunk(state, ks):
        return lax.scan(one_step, state, ks)

    _, outs = lax.scan(chunk, (state0, adjoint.init(model, q0)), jnp.arange(n_chunks * c).reshape(n_chunks, c))
    outs = jax.tree_util.tree_map(lambda x: x.reshape((n_chunks * c,) + x.shape[2:])[:n_steps], outs)
    if observe is None:
        records, result = outs, outs.result
        q = jnp.concatenate([q0[None], records.q])
        v = jnp.concatenate([v0[None], records.v])
    else:
        records, result = outs
        q = v = jnp.zeros((0, model.n_dof), dtype)
    ts = t0 + h * jnp.arange(n_steps + 1, dtype=dtype)
    if throw:  # the first failed step's member names the failure; simulate names its step and time
        failed = from_code(result) != RESULTS.successful
        first = from_code(result[jnp.argmax(failed)])
        ts = first.error_if(ts, jnp.any(failed))
    gap0 = model.unilateral(q0)
    return Trajectory(ts=ts, q=q, v=v, records=records, h=h, gap0=gap0)
