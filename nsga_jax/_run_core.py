"""The run core: one step body, and the loop that runs it in chunks.

Every driver takes its steps through :func:`advance`: step k of size h [s]
starts at ``t0 + k h`` (set on the state, never accumulated), then the
scheme steps, through the adjoint when a derivative is carried. How the steps
are looped is the driver's choice, as in diffrax where the adjoint picks the
loop:

- :func:`~nsga_jax.integrate` (pure, differentiable) runs :func:`advance` in
  a checkpointed ``lax.scan`` and keeps every record;
- :func:`~nsga_jax.simulate` and :func:`~nsga_jax.simulate_batch` (host
  drivers) run it in :func:`run_chunk`: up to ``length`` steps in one
  ``while_loop`` whose trip count is traced (one compilation for every chunk
  and every h), writing each step's record into packed buffers that the host
  unpacks (:func:`~nsga_jax._integrators.records.unpack_outputs`). A batch
  is the same loop with the step ``vmap``-ed over a leading member axis.

:func:`prepare_and_init` is the one preparation: the scheme's constant
operators at (h, t0) and its state at t0; :func:`constraints_at` gives the
gaps and bilateral values of every driver's initial record row.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax

from ._integrators.base import AbstractScheme, StepState
from ._integrators.operators import Operators
from ._integrators.records import StepOutput, output_template, pack_output, packed_sizes
from ._models.base import Model
from ._results import Result


def prepare_and_init(model: Model, scheme: AbstractScheme, t0, q0, v0, h) -> tuple[Operators, StepState]:
    """The scheme's constant operators for step h [s] at t0 [s] and its state
    at (t0, q0, v0), q0 and v0 of shape (n,)."""
    ops = scheme.prepare(model, h, t0)
    state = scheme.init(model, t0, q0, v0)
    return ops, state


def constraints_at(model: Model, q) -> tuple[jax.Array, jax.Array]:
    """The unilateral gaps [m] (nu,) and bilateral values (nb,) at q (n,):
    the initial row of every driver's records."""
    return model.unilateral(q), model.bilateral(q)


def advance(model: Model, scheme: AbstractScheme, ops: Operators, state: StepState, t, h, *,
            adjoint: Any = None, extra: Any = ()) -> tuple[StepState, StepOutput, Any]:
    """The one step body: a step of ``scheme`` of size h [s] from ``state`` at
    time t [s] (set on the state: times are ``t0 + k h``, never summed).

    ``adjoint`` (an :class:`~nsga_jax._adjoint.AbstractAdjoint`) chooses the
    derivative the step carries, with its ``extra`` from step to step; the
    host drivers carry none (``None``: the scheme's step as it is, CS
    included). Returns the new state, the step's record and the new ``extra``.
    """
    state = eqx.tree_at(lambda s: s.t, state, t)
    if adjoint is None:
        new, out = scheme.step(model, ops, state, h)
        return new, out, extra
    return adjoint.step(scheme, model, ops, state, extra, h)


def run_chunk(model: Model, scheme: AbstractScheme, ops: Operators, state: StepState, h, t_start, steps,
              stop_on_failure, length: int, members: bool = False):
    """Up to ``length`` steps in one ``while_loop``, each step's record packed
    (:func:`~nsga_jax._integrators.records.pack_output`) into float and integer
    buffers of ``length`` rows.

    Step i of the chunk starts at ``t_start + i h``. The loop takes ``steps``
    steps (traced, at most ``length``: the host plans the chunks, so no
    counter on the device passes a chunk's length), or stops after the first
    failed step when ``stop_on_failure``.

    With ``members=True`` every argument but ``stop_on_failure`` and
    ``length`` has a leading member axis (B,) (a batch passes
    ``stop_on_failure=False``: one failed member never stops the others):
    the step is ``vmap``-ed inside the loop (not the loop under ``vmap``,
    which would carry and select the whole record buffer at every step),
    member b takes ``steps[b]`` steps and then keeps its state, and the
    buffers are (B, length, fields).

    Returns the state after the chunk and ``(buffers, taken)``: the packed
    records and the mask of the rows that hold a step taken, (length,) or
    (B, length). Runs with another h or another number of steps reuse the
    compilation.
    """
    def one(model, scheme, ops, state, t, h):
        new, out, _ = advance(model, scheme, ops, state, t, h)
        return new, out

    step = jax.vmap(one) if members else one
    n_float, n_int = packed_sizes(output_template(model, state.q.dtype, scheme.subproblems))
    rows = (h.shape[0], length) if members else (length,)
    axis = len(rows) - 1
    buffers = (jnp.zeros((*rows, n_float), state.q.dtype), jnp.zeros((*rows, n_int), jnp.int32))
    taken = jnp.zeros(rows, bool)
    pack = jax.vmap(pack_output) if members else pack_output

    def going(carry):
        i, _, stopped, _, _ = carry
        return (i < length) & jnp.any(i < steps) & ~stopped

    def body(carry):
        i, state, stopped, buffers, taken = carry
        do = i < steps
        t = t_start + i.astype(h.dtype) * h
        # set here too, so that a finished member keeps this state: selecting against the state
        # before the update measured 10 % slower a step (double pendulum, 64 members)
        state = eqx.tree_at(lambda s: s.t, state, t)
        new, out = step(model, scheme, ops, state, t, h)
        if members:  # a member past its steps keeps its state
            new = jax.tree_util.tree_map(lambda a, b: jnp.where(do.reshape(-1, *([1] * (a.ndim - 1))), a, b),
                                         new, state)
        buffers = tuple(lax.dynamic_update_index_in_dim(b, x, i, axis) for b, x in zip(buffers, pack(out)))
        taken = lax.dynamic_update_index_in_dim(taken, do, i, axis)
        if stop_on_failure is not False:  # a batch never stops: leave the test out of its loop
            stopped = stopped | (jnp.any(out.result != int(Result.successful)) & stop_on_failure)
        return i + 1, new, stopped, buffers, taken

    init = (jnp.zeros((), jnp.int32), state, jnp.zeros((), bool), buffers, taken)
    _, state, _, buffers, taken = lax.while_loop(going, body, init)
    return state, (buffers, taken)
