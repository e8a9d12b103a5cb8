"""Many step sizes of one problem in one compiled program: ``vmap`` over h.

The runs have different step counts, so the scan is padded to the longest run
and each member's extra steps are masked (they leave its state unchanged and
are dropped from its records). Every member pays the longest run's number of
steps: batching pays when the step sizes are close, and loses to separate runs
when they spread over decades (``experiments/bench_batch_h.py`` measures both;
:func:`~nsga_jax.studies.run_step_sizes` picks by that rule).
"""

from __future__ import annotations

import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._simulate import (
    DTYPES,
    Observe,
    Solution,
    _cast,
    _check_finite_positive,
    _float64_view,
    _n_steps,
    _prepare_and_init_raw,
    _prepend_initial,
    _run_chunk,
    precision,
    validate_initial_state,
    validate_model,
    validate_scheme,
)
from .integrators.base import AbstractScheme
from .models.base import Model
from .results import ConfigError, Result


def _run_chunk_batch(model, scheme, ops, carry, h, n_steps, stop_on_failure, length):
    return jax.vmap(
        lambda o, c, hh, n: _run_chunk(model, scheme, o, c, hh, n, stop_on_failure, length)
    )(ops, carry, h, n_steps)


_run_chunk_batch_jit = eqx.filter_jit(_run_chunk_batch)


@eqx.filter_jit
def _prepare_and_init_batch(model, scheme, t0, q0, v0, hs):
    return jax.vmap(lambda h: _prepare_and_init_raw(model, scheme, t0, q0, v0, h))(hs)


def simulate_batch(
    model: Model,
    scheme: AbstractScheme,
    t0: float,
    t1: float,
    hs,
    q0,
    v0,
    *,
    chunk_size: int = 4096,
    observe: Observe | None = None,
    dtype: str = "float64",
) -> list[Solution]:
    """Integrate one problem with every step size in ``hs`` at once (``vmap``).

    Failures never stop the batch (one bad member must not kill a sweep): each
    member's records carry its result codes and ``Solution.result`` its first
    failure. ``wall_time`` and ``compile_time`` are those of the whole batch.
    ``dtype`` is the precision, as in :func:`~nsga_jax.simulate`.
    """
    validate_scheme(scheme)
    validate_model(model)
    hs = np.asarray([_check_finite_positive("h", h) for h in np.atleast_1d(hs)])
    t0, t1 = float(t0), float(t1)
    if not t1 > t0:
        raise ConfigError(f"t1 must be greater than t0, got t0={t0}, t1={t1}")
    if hs.max() > t1 - t0:
        raise ConfigError(f"h must be in (0, t1 - t0] = (0, {t1 - t0}], got {hs.max()}")
    q0 = np.asarray(q0, dtype=float).reshape(-1)
    v0 = np.asarray(v0, dtype=float).reshape(-1)
    validate_initial_state(model, q0, v0)
    if dtype not in DTYPES:
        raise ConfigError(f"dtype must be one of {', '.join(map(repr, DTYPES))}, got {dtype!r}")
    with precision(dtype):
        solutions = _integrate_batch(*_cast((model, scheme), dtype), t0, t1, hs, q0.astype(dtype),
                                     v0.astype(dtype), chunk_size)
    if observe is not None:
        for sol in solutions:
            sol.observables = {k: np.asarray(v) for k, v in observe(_float64_view(sol)).items()}
    return solutions


def _integrate_batch(model, scheme, t0, t1, hs, q0, v0, chunk_size) -> list[Solution]:
    """The batched loop of :func:`simulate_batch` on validated arguments, in the
    precision already set by the caller."""
    n_steps = np.array([_n_steps(t0, t1, h) for h in hs])
    longest = int(n_steps.max())
    n_chunks = -(-longest // chunk_size)
    length = -(-longest // n_chunks)
    B = len(hs)

    args0 = (model, scheme, jnp.asarray(t0), jnp.asarray(q0), jnp.asarray(v0), jnp.asarray(hs))
    tc = time.perf_counter()
    prep = _prepare_and_init_batch.lower(*args0).compile()
    compile_time = time.perf_counter() - tc
    tw = time.perf_counter()
    ops, state = prep(*args0)
    jax.block_until_ready(state)
    wall = time.perf_counter() - tw

    carry = (state, jnp.zeros((B,), jnp.int32), jnp.zeros((B,), bool))
    consts = (jnp.asarray(hs), jnp.asarray(n_steps), jnp.asarray(False))
    tc = time.perf_counter()
    run = _run_chunk_batch_jit.lower(model, scheme, ops, carry, *consts, length).compile()
    compile_time += time.perf_counter() - tc

    chunks: list[list] = [[] for _ in range(B)]
    for _ in range(n_chunks):
        tw = time.perf_counter()
        carry, (out, done) = run(model, scheme, ops, carry, *consts, length)
        jax.block_until_ready((carry, out, done))
        wall += time.perf_counter() - tw
        out, done = jax.device_get((out, done))
        for b in range(B):
            if done[b].any():
                chunks[b].append(jax.tree_util.tree_map(lambda x: x[b][done[b]], out))

    solutions = []
    for b in range(B):
        records = _prepend_initial(model, chunks[b], t0, q0, v0)
        codes = np.asarray(records.result)
        bad = np.nonzero(codes != Result.successful)[0]
        sol = Solution(
            ts=np.asarray(records.t), q=np.asarray(records.q), v=np.asarray(records.v), records=records,
            h=float(hs[b]), n_steps=len(records.t) - 1, n_steps_requested=int(n_steps[b]),
            result=Result(int(codes[bad[0]])) if bad.size else Result.successful,
            wall_time=wall, compile_time=compile_time,
        )
        solutions.append(sol)
    return solutions
