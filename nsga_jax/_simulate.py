"""The time loop: ``simulate(model, scheme, t0, t1, h, q0, v0)``.

The host driver over the step of the pure :func:`~nsga_jax.integrate`; both
return a :class:`~nsga_jax.Solution`. The whole trajectory runs in compiled
loops over chunks of steps (one compilation, reused for every chunk); no Python
runs inside a chunk. After each chunk the host adds the chunk to the run's
statistics, keeps its records (every ``SaveAt.every``-th step of them), reports
progress, gathers the kept records into few files in ``SaveAt.chunks``
(:class:`~nsga_jax._chunks.RecordFiles`, written at the latest every few
seconds and when the run stops or is interrupted), hands the full chunk to an
optional callback, and stops early on a failure when ``throw=True``. With
``SaveAt(every=k > 1)`` the memory a run holds is one chunk plus the kept
records: flat for any number of steps.

Compile time is measured apart (``lower().compile()``); ``wall_time`` is the
execution time of the constant-operator preparation, the initialisation and
all chunks (until their results are ready; copying them to NumPy is not
counted).
"""

from __future__ import annotations

import time
import warnings as _warnings
from collections.abc import Callable
from typing import Any, cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._chunks import RecordFiles, chunk_length, chunk_plan
from ._compilation_cache import cache_events, compile_source
from ._diagnosis import FLOAT32_HINT, nonfinite_origin
from ._first_step import LIMIT_SECONDS, NOTE_SECONDS, check_first_step
from ._integrators.base import AbstractScheme
from ._integrators.records import StepOutput, output_template, unpack_outputs
from ._memory import check_fits, kept_records
from ._models.base import Model
from ._monitors import (
    ENERGY_WARNING,
    RunTotals,
    Tolerances,
    coarse_step_warning,
    default_tolerances,
    invariant_warnings,
)
from ._precision import cast_floats
from ._progress import Progress
from ._results import ConvergenceError, InvariantError, Result
from ._run_core import constraints_at, prepare_and_init, run_chunk
from ._run_inputs import check_run_inputs
from ._saveat import DEVICE_ONLY, SaveAt, refuse
from ._solution import Observables, Solution, host_solution, with_observables
from ._validation import integer, require_instance

# filter_jit's wrappers have ``lower`` (compiled ahead of the run); their declared types are the bare functions'
_run_chunk_jit = cast(Any, eqx.filter_jit(run_chunk))
_prepare_and_init = cast(Any, eqx.filter_jit(prepare_and_init))


def simulate(
    model: Model,
    scheme: AbstractScheme,
    t0: float,
    t1: float,
    h: float,
    q0,
    v0,
    *,
    saveat: SaveAt = SaveAt(),
    throw: bool = True,
    chunk_size: int | None = None,
    progress: bool = False,
    on_chunk: Callable[[int, StepOutput], None] | None = None,
    observables: Observables | None = None,
    dtype: str = "float64",
    strict: bool = False,
    tolerances: Tolerances | None = None,
    check_memory: bool = True,
    first_step_limit: float | None = LIMIT_SECONDS,
) -> Solution:
    """Integrate ``model`` from t0 to t1 [s] with step h [s] by ``scheme`` (host driver).

    The same step and the same :class:`~nsga_jax.Solution` as the pure
    :func:`~nsga_jax.integrate`, driven from the host: progress, chunks
    written to disk, a named :class:`ConvergenceError`, float32 runs, energy
    and constraint monitors, timings. The solution's leaves are NumPy arrays.

    Args:
        model: the semi-discrete system.
        scheme: the time integrator: ``DS(rho_inf=0.8)``, ``DSn()``, ``CS()`` or ``MJ(theta=0.5)``.
        t0, t1, h: start and end time and step size [s]; N = floor((t1-t0)/h)
            steps, step k at t0 + k h (computed in float64, never accumulated).
        q0, v0: initial coordinates and velocities, shape (n,).
        saveat: what to keep (:class:`~nsga_jax.SaveAt`): ``every=k`` keeps
            the records of every k-th step (and of the last) in the solution,
            while ``stats``, ``failed_steps`` and ``on_chunk`` still see every
            step (memory stays flat for long runs); ``chunks=folder`` writes
            the kept records to that folder as the run goes (few files,
            :class:`~nsga_jax._chunks.RecordFiles`; written at once on an
            interruption). ``SaveAt.fn`` is for :func:`~nsga_jax.integrate` and is
            refused here.
        throw: stop at the first step that fails (Newton cap or NaN/inf) and
            raise :class:`ConvergenceError`; with ``False`` keep going and
            mark failed steps in ``records.result``.
        chunk_size: steps per compiled chunk (default: :func:`chunk_length`, from
            the model's size; every chunk, and every run of the same model
            structure whatever its h or parameter values, reuses one compilation).
        progress: print progress on stderr (at most twice a second).
        on_chunk: called as ``on_chunk(k, records)`` after chunk k with that
            chunk's records (a :class:`~nsga_jax.StepOutput` of NumPy arrays).
        observables: ``Solution -> {name: array}``, named quantities computed
            from the finished solution (a scene's observables), stored in
            ``Solution.observables``.
        dtype: ``"float64"`` (default) or ``"float32"``: the precision of the
            whole run (model, state, operators, records): the model's and
            scheme's leaves, q0, v0, h and t0 are cast to it and every array
            the step creates follows them (``jax_enable_x64`` is left as it
            is; float64 needs it on). In float32 the
            round-off of an assembled stiff force can exceed eq. 51's bound at
            the default ``tol_r = 1e-5``.
        strict: raise :class:`InvariantError` when the energy rises at an
            impact step past ``tolerances.impact_energy`` (by default a
            warning in ``Solution.warnings``).
        tolerances: the monitors' bounds (:class:`~nsga_jax._monitors.Tolerances`).
        check_memory: refuse, before compiling, a run whose dense iteration
            matrices and kept records would not fit in the available memory
            (:func:`~nsga_jax._memory.check_fits`); ``False`` (or the
            environment variable ``NSGA_JAX_SKIP_MEMORY_CHECK=1``) skips it.
        first_step_limit: refuse, before compiling, a run on the dense path
            whose first step is estimated above this many seconds (60 by
            default; :func:`~nsga_jax._first_step.check_first_step`); ``None``
            runs anyway. An estimate above 5 s is shown with the compiling
            line, and the first chunk is then one step.

    Everything is validated before anything is traced: wrong Python types
    raise :class:`TypeError`, bad values :class:`ConfigError`. Under
    ``jax.grad``, ``jit`` or ``vmap`` (traced inputs) it refuses, naming
    :func:`~nsga_jax.integrate`, the pure entry point with the same arguments.
    """
    run_inputs = check_run_inputs("nsga_jax.simulate", model, scheme, t0, t1, q0, v0, dtype=dtype, h=h,
                                  observables=observables, first_step_limit=first_step_limit)
    dtype, t0, q0, v0, notes = run_inputs.dtype, run_inputs.t0, run_inputs.q0, run_inputs.v0, run_inputs.notes
    h, n_steps = float(run_inputs.hs[0]), int(run_inputs.n_steps[0])
    refuse(saveat, DEVICE_ONLY, "simulate (host driver)", "nsga_jax.integrate, the pure entry point")
    record_every = saveat.every
    if chunk_size is not None:
        chunk_size = integer("chunk_size", chunk_size, 1)
    for name, value in (("throw", throw), ("progress", progress), ("strict", strict), ("check_memory", check_memory)):
        require_instance(name, value, (bool, np.bool_), "True or False")
    if on_chunk is not None and not callable(on_chunk):
        raise TypeError(f"on_chunk must be a function or None, got {type(on_chunk).__name__}")
    tolerances = default_tolerances(dtype) if tolerances is None else tolerances
    require_instance("tolerances", tolerances, Tolerances, "a nsga_jax.Tolerances")
    records, record_numbers = kept_records(model, scheme, n_steps, record_every)
    check_fits(model, scheme, np.dtype(dtype).itemsize, records=records, record_numbers=record_numbers,
               enabled=check_memory)
    slow = check_first_step(model, scheme, dtype, limit=first_step_limit)
    warnings = [w for w in [coarse_step_warning(model.angular_speed(q0, v0), h, tolerances)] if w]
    run, totals, error = _host_loop(*cast_floats((model, scheme), dtype), t0, n_steps, h, q0.astype(dtype),
                                    v0.astype(dtype), throw=throw, chunk_size=chunk_size, progress=progress,
                                    on_chunk=on_chunk, record_every=record_every, dtype=dtype,
                                    files=None if saveat.chunks is None else RecordFiles(saveat.chunks),
                                    estimate=slow.describe() if slow.seconds > NOTE_SECONDS else None)
    frictional_restitution = (bool(model.n_friction) and bool(np.any(np.asarray(model.restitution) > 0))
                              and getattr(scheme, "impact_law", "newton") != "energetic")  # the option is in use
    warnings += invariant_warnings(totals, tolerances, h, t0, frictional_restitution)
    for message in warnings:
        _warnings.warn(message, InvariantWarning, stacklevel=2)
    sol = with_observables(host_solution(**run, totals=totals, warnings=notes + warnings), observables)
    if error is not None:
        error.solution = sol
        raise error
    if strict and any(w.startswith(ENERGY_WARNING) for w in sol.warnings):
        raise InvariantError(next(w for w in sol.warnings if w.startswith(ENERGY_WARNING)), sol)
    return sol


class InvariantWarning(UserWarning):
    """A monitor past its tolerance (penetration, bilateral violation, energy
    created at an impact, a coarse step): the run went on, its result may be
    wrong there."""


def _energies(model: Model, q: jax.Array, v: jax.Array) -> jax.Array:
    """Total energy [J] and kinetic energy 1/2 v·M v [J] after each step of a
    chunk: q, v (steps, n) -> (steps, 2)."""
    return jax.vmap(lambda qi, vi: jnp.stack([model.energy(qi, vi), 0.5 * vi @ model.mass_product(qi, vi)]))(q, v)


_energies_jit = eqx.filter_jit(_energies)  # one function for every run: later runs reuse its compilation


def _energy_of(model: Model):
    """The jitted :func:`_energies` for a model that has an energy, else ``None``."""
    return _energies_jit if model.has_energy else None


def _host_loop(model, scheme, t0, n_steps, h, q0, v0, *, throw, chunk_size, progress, on_chunk, record_every,
               dtype, files=None, estimate=None) -> tuple[dict[str, Any], RunTotals, ConvergenceError | None]:
    """The time loop of :func:`simulate` on validated arguments, in ``dtype``
    (that of the model, scheme, q0 and v0 it is given); returns the solution's pieces (the arguments of
    :func:`~nsga_jax._solution.host_solution`), the running totals and, when
    ``throw`` and a step failed, the error to raise. ``files``: the
    :class:`~nsga_jax._chunks.RecordFiles` the kept records go to, flushed
    however the loop ends. ``estimate``: the first
    step's, shown while compiling, where it is long (the first chunk is then one step; later
    chunks hold the steps of about :data:`~nsga_jax._progress.EVERY_SECONDS`)."""
    length = chunk_size or chunk_length(model)
    real = np.dtype(dtype).type

    args0 = (model, scheme, jnp.asarray(t0, dtype), jnp.asarray(q0), jnp.asarray(v0), jnp.asarray(h, dtype))
    shown = Progress(n_steps, t0, h, progress)
    tc = started = shown.compiling(model.n_dof, estimate)  # a long first step: a first chunk of one
    with cache_events() as cached_prep:
        prep = _prepare_and_init.lower(*args0).compile()
    compile_time = time.perf_counter() - tc

    tw = time.perf_counter()
    ops, state = prep(*args0)
    jax.block_until_ready(state)
    wall = time.perf_counter() - tw
    state0 = state

    template = output_template(model, state.q.dtype, scheme.subproblems)
    h_arr, stop = jnp.asarray(h, dtype), jnp.asarray(throw)
    shapes = (jnp.asarray(real(t0)), jnp.asarray(length, jnp.int32))
    tc = time.perf_counter()
    with cache_events() as cached:
        run = _run_chunk_jit.lower(model, scheme, ops, state, h_arr, *shapes, stop, length).compile()
        energy_of = _energy_of(model)
        if energy_of is not None:
            q_shape = jnp.zeros((length, model.n_dof), state.q.dtype)
            energy_of = energy_of.lower(model, q_shape, q_shape).compile()
    compile_time += time.perf_counter() - tc
    cached = {k: cached[k] + cached_prep[k] for k in cached}
    shown.compiled(started, compile_source(cached))

    chunks, numbers = [], []
    totals = RunTotals(n_bilateral=model.n_bilateral)
    if model.n_unilateral:
        gap0, gap_rate0 = jax.jvp(model.unilateral, (jnp.asarray(q0),), (jnp.asarray(v0),))
        totals.start_gaps(gap0, gap_rate0, h)
    if energy_of is not None:  # E(q0, v0), from the chunk's program (no other compilation)
        rows = (jnp.broadcast_to(jnp.asarray(q0), (length, model.n_dof)),
                jnp.broadcast_to(jnp.asarray(v0), (length, model.n_dof)))
        totals.start(*np.asarray(energy_of(model, *rows)[0], float))
    first_failure = None
    steps_done = 0
    try:
        for k, (first, count) in enumerate(chunk_plan(n_steps, length, cap=shown.next_chunk)):
            tw = time.perf_counter()
            t_start = jnp.asarray(real(t0 + (first - 1) * h))
            state, (packed, done) = run(model, scheme, ops, state, h_arr, t_start, jnp.asarray(count, jnp.int32),
                                        stop, length)
            jax.block_until_ready((state, packed, done))
            wall += time.perf_counter() - tw
            packed, done = jax.device_get((packed, done))
            floats, ints = packed
            full = unpack_outputs(floats, ints, template)
            energies = None if energy_of is None else np.asarray(energy_of(model, full.q, full.v))[done]
            out = jax.tree_util.tree_map(lambda x: x[done], full)
            if on_chunk is not None:
                on_chunk(k, out)
            totals.add(out, first_step=first, energies=energies)
            steps_done += len(out.t)
            bad = np.nonzero(out.result != Result.successful)[0]
            if first_failure is None and bad.size:
                i = int(bad[0])
                first_failure = (first + i, out, i)
            halt = throw and first_failure is not None
            last = halt or steps_done >= n_steps
            kept, kept_numbers = _every(out, first, record_every, keep_last=last)
            chunks.append(kept)
            numbers.append(kept_numbers)
            if files is not None:
                files.add(kept)
            shown.chunk(steps_done, last)
            if halt:
                break
    finally:
        if files is not None:
            files.flush()  # also on Ctrl-C: what was kept is on disk

    records = prepend_initial(model, chunks, t0, q0, v0)
    ts = t0 + h * np.concatenate([[0], *numbers]).astype(np.float64)
    run = dict(
        records=records,
        ts=ts,
        h=h,
        n_steps=steps_done,
        n_steps_requested=n_steps,
        result=Result.successful if first_failure is None else Result(int(first_failure[1].result[first_failure[2]])),
        wall_time=wall,
        compile_time=compile_time,
        compile_source=compile_source(cached),
    )
    if not (throw and first_failure is not None):
        return run, totals, None
    step, out, i = first_failure
    result = Result(int(out.result[i]))
    names = out.newton.names
    if result.subproblem in names:
        name = result.subproblem
    else:  # no sub-problem of this scheme named: report the one furthest from its bound
        name = names[int(np.argmax(out.newton.residual[i] / np.maximum(out.newton.tolerance[i], 1e-300)))]
    failed = out.newton[name]
    err = ConvergenceError(
        step=step,
        time=t0 + step * h,
        result=result,
        residual=float(failed.residual[i]),
        tolerance=float(failed.tolerance[i]),
        hint=(FLOAT32_HINT if dtype == "float32" and result.capped
              else nonfinite_origin(ops, state0) if result.nonfinite else ""),
    )
    return run, totals, err


def _every(records: StepOutput, first_step: int, k: int, keep_last: bool) -> tuple[StepOutput, np.ndarray]:
    """The records of the steps whose number is a multiple of ``k`` (and the
    chunk's last step if ``keep_last``), with their step numbers; the chunk
    starts at step ``first_step``."""
    numbers = first_step + np.arange(len(records.t))
    if k == 1:
        return records, numbers
    keep = numbers % k == 0
    if keep_last and len(keep):
        keep[-1] = True
    return jax.tree_util.tree_map(lambda x: x[keep], records), numbers[keep]


# one compiled call, shared by every model of one structure: op by op, the box stack's constraints took
# 2.0 s on first use (each operation compiled) and 22 ms after; compiled, 0.23 s and 0.3 ms
_constraints_at_jit = eqx.filter_jit(constraints_at)


def prepend_initial(model: Model, chunks: list[StepOutput], t0, q0, v0, constraints=None) -> StepOutput:
    """Concatenate the chunks after a zero record holding the initial state;
    ``constraints``: its (gaps, bilateral values) where known (a batch
    computes every member's at once), else computed here."""
    first = chunks[0]
    init = jax.tree_util.tree_map(lambda x: np.zeros((1,) + x.shape[1:], x.dtype), first)
    if constraints is None:
        constraints = _constraints_at_jit(model, jnp.asarray(q0))
    gap, bil = (np.asarray(x) for x in jax.device_get(constraints))
    init = eqx.tree_at(
        lambda r: (r.t, r.q, r.v, r.gap, r.bilateral),
        init,
        (np.array([t0]), q0[None], v0[None], gap[None], bil[None]),
    )
    return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs, axis=0), init, *chunks)
