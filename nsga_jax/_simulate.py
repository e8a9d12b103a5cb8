"""The time loop: ``simulate(model, scheme, t0, t1, h, q0, v0)``.

The whole trajectory runs in compiled loops over chunks of steps
(one compilation, reused for every chunk); no Python runs inside a chunk. After
each chunk the host adds the chunk to the run's statistics, keeps its records
(every ``record_every``-th step of them), reports progress, hands the full
chunk to an optional callback (the CLI writes it to disk at once), and stops
early on a failure when ``throw=True``. With ``record_every > 1`` the memory a
run holds is one chunk plus the kept records: flat for any number of steps.

Compile time is measured apart (``lower().compile()``); ``wall_time`` is the
execution time of the constant-operator preparation, the initialisation and
all chunks (until their results are ready; copying them to NumPy is not
counted).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .integrators.base import (
    AbstractScheme,
    Operators,
    StepOutput,
    StepState,
    output_template,
    pack_output,
    packed_sizes,
    unpack_outputs,
)
from .models.base import Model
from .results import SUBPROBLEMS, ConfigError, ConvergenceError, Result

Observe = Callable[["Solution"], dict[str, np.ndarray]]



@dataclass
class Solution:
    """A trajectory and what the scheme did to get it (NumPy arrays, host side).

    Every per-time array has a leading axis of length N + 1 (the initial state
    first), or, with ``record_every = k > 1``, one entry per k steps plus the
    initial and the last step. Record fields (``impulse``, ``nu``, ``lam``,
    ``iterations``, ``result``...) are zero at index 0. ``stats`` and
    ``failed_steps`` always cover every step.

    Attributes:
        ts: times [s], (N+1,).
        q, v: coordinates and velocities, (N+1, n).
        records: :class:`~nsga_jax.integrators.ds.StepOutput` with NumPy leaves, (N+1, ...).
        observables: named scene quantities, each (N+1,).
        h: step size [s]; n_steps: steps actually taken (fewer than requested
            when a failure stopped the run).
        result: the first failure's :class:`Result` (``successful`` if none).
        totals: statistics over every step (accumulated while running; computed
            from ``records`` when not given).
        stats: iteration statistics, failures, constraint violations, timings.
    """

    ts: np.ndarray
    q: np.ndarray
    v: np.ndarray
    records: StepOutput
    h: float
    n_steps: int
    n_steps_requested: int
    result: Result
    wall_time: float
    compile_time: float
    observables: dict[str, np.ndarray] = field(default_factory=dict)
    totals: RunTotals | None = None

    def __post_init__(self):
        if self.totals is None:
            self.totals = RunTotals()
            self.totals.add(jax.tree_util.tree_map(lambda x: np.asarray(x)[1:], self.records), first_step=1)

    @property
    def iterations(self) -> np.ndarray:
        """Newton iterations (N+1, 3): smooth, position, velocity."""
        return np.asarray(self.records.iterations)

    @property
    def failed_steps(self) -> np.ndarray:
        """Step numbers k (t = t0 + k h) of the steps whose result is not
        successful; indices into ``ts`` when every step is recorded."""
        return np.asarray(self.totals.failed, dtype=int)

    @property
    def impulse(self) -> np.ndarray:
        """Constraint impulses Λ [N s], (N+1, nc), bilaterals first."""
        return np.asarray(self.records.impulse)

    @property
    def gap(self) -> np.ndarray:
        """Unilateral gaps g^U(q) [m], (N+1, nu)."""
        return np.asarray(self.records.gap)

    @property
    def stats(self) -> dict:
        tot = self.totals
        n = max(tot.n_steps, 1)
        stats = {
            "n_steps": int(self.n_steps),
            "h": float(self.h),
            "wall_time_s": float(self.wall_time),
            "compile_time_s": float(self.compile_time),
            "us_per_step": 1e6 * float(self.wall_time) / max(int(self.n_steps), 1),
            "iterations": {
                name: {"mean": float(tot.iterations_sum[i] / n), "max": int(tot.iterations_max[i])}
                for i, name in enumerate(("smooth", "position", "velocity"))
            },
            "failed_steps": len(tot.failed),
            "result": self.result.name,
            "max_penetration": float(max(0.0, -tot.min_gap)),
            "max_bilateral_violation_position": float(tot.max_bilateral),
            "max_bilateral_violation_velocity": float(tot.max_bilateral_rate),
        }
        stats["iterations"]["linear_solves"] = {"mean": float(tot.solves_sum / n), "max": int(tot.solves_max)}
        return stats


@dataclass
class RunTotals:
    """Statistics over every step of a run, added chunk by chunk, so that they
    cover the steps a strided record leaves out: Newton iterations (sum and max
    per sub-problem, and of their total, the linear solves per step), failed
    step numbers and the first one's result code, the smallest gap [m] and the largest bilateral violations
    (position [m], velocity [m/s])."""

    n_steps: int = 0
    iterations_sum: np.ndarray = field(default_factory=lambda: np.zeros(3))
    iterations_max: np.ndarray = field(default_factory=lambda: np.zeros(3, int))
    solves_sum: float = 0.0
    solves_max: int = 0
    failed: list[int] = field(default_factory=list)
    first_result: int = 0
    min_gap: float = math.inf
    max_bilateral: float = 0.0
    max_bilateral_rate: float = 0.0

    def add(self, records: StepOutput, first_step: int) -> None:
        """Add consecutive steps ``first_step, first_step + 1, ...`` (NumPy records)."""
        it = np.asarray(records.iterations)
        if not len(it):
            return
        self.n_steps += len(it)
        self.iterations_sum += it.sum(axis=0)
        self.iterations_max = np.maximum(self.iterations_max, it.max(axis=0))
        solves = it.sum(axis=1)
        self.solves_sum += float(solves.sum())
        self.solves_max = max(self.solves_max, int(solves.max()))
        bad = np.nonzero(np.asarray(records.result) != Result.successful)[0]
        if bad.size and not self.failed:
            self.first_result = int(np.asarray(records.result)[bad[0]])
        self.failed.extend((first_step + bad).tolist())
        gap = np.asarray(records.gap)
        if gap.size:
            self.min_gap = min(self.min_gap, float(gap.min()))
        self.max_bilateral = max(self.max_bilateral, _absmax(records.bilateral))
        self.max_bilateral_rate = max(self.max_bilateral_rate, _absmax(records.bilateral_rate))


def _absmax(x) -> float:
    x = np.asarray(x)
    return float(np.abs(x).max()) if x.size else 0.0


# ----------------------------------------------------------------- validation


def _check_finite_positive(name: str, value, allow_zero: bool = False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(x):
        raise ConfigError(f"{name} must be finite, got {x}")
    if x < 0 or (x == 0 and not allow_zero):
        rng = "[0, inf)" if allow_zero else "(0, inf)"
        raise ConfigError(f"{name} must be in {rng}, got {x}")
    return x


def validate_scheme(scheme: AbstractScheme) -> None:
    for name in ("tol_r", "tol_f"):
        _check_finite_positive(name, getattr(scheme, name))
    if not (isinstance(scheme.max_iter, int) and scheme.max_iter >= 1):
        raise ConfigError(f"max_iter must be an integer >= 1, got {scheme.max_iter!r}")
    for name, (value, lo, hi) in scheme.bounds().items():
        x = float(value)
        if not (math.isfinite(x) and lo <= x <= hi):
            raise ConfigError(f"{name} must be in [{lo:g}, {hi:g}], got {x}")


def validate_model(model: Model) -> None:
    """Every float field finite, each named field in its :attr:`Model.ranges`,
    and the model's own rules (:meth:`Model.invalid`), on concrete values."""
    cls = type(model).__name__
    for path, leaf in jax.tree_util.tree_leaves_with_path(model):
        if eqx.is_inexact_array(leaf) and not isinstance(leaf, jax.core.Tracer):
            if not np.all(np.isfinite(np.asarray(leaf))):
                raise ConfigError(f"{cls}{jax.tree_util.keystr(path)} must be finite, got {np.asarray(leaf).tolist()}")
    for name, rng in model.ranges.items():
        value = getattr(model, name)
        if isinstance(value, jax.core.Tracer):
            continue
        value = np.asarray(value)
        if not rng.contains(value):
            raise ConfigError(f"{cls}.{name} must be in {rng.text()}, got {value.tolist()}")
    traced = any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(model))
    message = None if traced else model.invalid()
    if message:
        raise ConfigError(f"{cls}.{message}")


def validate_initial_state(model: Model, q0: np.ndarray, v0: np.ndarray, tol: float = 1e-9) -> None:
    """Shapes, finiteness, bilateral constraints and non-penetration at t0."""
    n = model.n_dof
    for name, x in (("q0", q0), ("v0", v0)):
        if x.shape != (n,):
            raise ConfigError(f"{name} must have shape ({n},), got {x.shape}")
        if not np.all(np.isfinite(x)):
            bad = np.nonzero(~np.isfinite(x))[0]
            raise ConfigError(f"{name} must be finite; non-finite entries at indices {bad.tolist()}")
    scale = max(1.0, float(np.abs(q0).max(initial=0.0)))
    if model.n_unilateral:
        gap = np.asarray(model.unilateral(jnp.asarray(q0)))
        if not np.all(np.isfinite(gap)):
            raise ConfigError("the initial gaps are not finite")
        bad = np.nonzero(gap < -tol * scale)[0]
        if bad.size:
            j = int(bad[0])
            raise ConfigError(
                f"initial penetration: gap {j} is {gap[j]:.6g} m at t0; every gap must be >= 0 "
                "(move the body out of the obstacle)"
            )
    if model.n_bilateral:
        g = np.asarray(model.bilateral(jnp.asarray(q0)))
        bad = np.nonzero(~(np.abs(g) <= 1e3 * tol * scale))[0]
        if bad.size:
            j = int(bad[0])
            raise ConfigError(
                f"the initial position violates bilateral constraint {j} (g = {g[j]:.6g}); "
                "start from a configuration that satisfies the joints"
            )


def _n_steps(t0: float, t1: float, h: float) -> int:
    n = (t1 - t0) / h
    return max(1, int(math.floor(n + 1e-9)))


# --------------------------------------------------------------------- the loop


def _run_chunk(model, scheme, ops, carry, h, n_steps, stop_on_failure, length):
    """Up to ``length`` steps of ``scheme`` in one ``while_loop``, writing each
    step's record (packed in two vectors, :func:`pack_output`) into buffers of
    ``length`` records, returned as they are (the host unpacks them into
    views, :func:`unpack_outputs`). The loop stops after step
    ``n_steps`` (or after a failure when ``stop_on_failure``); the buffer's
    unused tail is marked not done and dropped by the caller. The step count is
    a traced value, so runs with another h (another number of steps) reuse the
    compilation; under ``vmap`` a member that has finished keeps its state."""
    state, k, stopped = carry
    template = output_template(model, state.q.dtype)
    n_float, n_int = packed_sizes(template)
    buffer = (jnp.zeros((length, n_float), state.q.dtype), jnp.zeros((length, n_int), jnp.int32))

    def going(c):
        i, _, k, stopped, _ = c
        return (i < length) & (k < n_steps) & ~stopped

    def body(c):
        i, state, k, stopped, buffer = c
        state, out = scheme.step(model, ops, state, h)
        buffer = tuple(lax.dynamic_update_index_in_dim(b, x, i, 0) for b, x in zip(buffer, pack_output(out)))
        failed = out.result != Result.successful
        return i + 1, state, k + 1, stopped | (failed & stop_on_failure), buffer

    i, state, k, stopped, buffer = lax.while_loop(going, body, (jnp.zeros((), k.dtype), state, k, stopped, buffer))
    return (state, k, stopped), (buffer, jnp.arange(length) < i)


def chunk_length(model: Model) -> int:
    """Steps per compiled chunk, from the model's size alone (so h and parameter
    values never change it): a power of two between 64 and 4096, about 2**18
    recorded numbers per chunk (4096 steps for a ball, 512 for the 201-node
    bar, 128 for the 648-dof cube)."""
    fit = 2**18 // (2 * model.n_dof + 16)
    return int(min(4096, max(64, 2 ** int(math.floor(math.log2(max(fit, 1)))))))


_run_chunk_jit = eqx.filter_jit(_run_chunk)


def _prepare_and_init_raw(model, scheme, t0, q0, v0, h):
    ops = scheme.prepare(model, h, t0)
    state = scheme.init(model, t0, q0, v0)
    return ops, state


_prepare_and_init = eqx.filter_jit(_prepare_and_init_raw)


def simulate(
    model: Model,
    scheme: AbstractScheme,
    t0: float,
    t1: float,
    h: float,
    q0,
    v0,
    *,
    throw: bool = True,
    chunk_size: int | None = None,
    progress: bool = False,
    on_chunk: Callable[[int, "Solution"], None] | None = None,
    observe: Observe | None = None,
    record_every: int = 1,
    dtype: str = "float64",
) -> Solution:
    """Integrate ``model`` from t0 to t1 [s] with step h [s] by ``scheme``.

    Args:
        model: the semi-discrete system.
        scheme: the time integrator: ``DS(rho_inf=0.8)``, ``DSn()``, ``CS()`` or ``MJ(theta=0.5)``.
        t0, t1, h: start and end time and step size [s]; N = floor((t1-t0)/h) steps.
        q0, v0: initial coordinates and velocities, shape (n,).
        throw: stop at the first step that fails (Newton cap or NaN/inf) and
            raise :class:`ConvergenceError`; with ``False`` keep going and
            mark failed steps in ``records.result``.
        chunk_size: steps per compiled chunk (default: :func:`chunk_length`, from
            the model's size; every chunk, and every run of the same model
            structure whatever its h or parameter values, reuses one compilation).
        progress: print progress on stderr after each chunk.
        on_chunk: called as ``on_chunk(k, partial)`` after chunk k with that
            chunk's records (a :class:`Solution` of the chunk alone).
        observe: computes named observables from the finished solution.
        record_every: keep the records of every k-th step (and of the last) in
            the solution; ``stats``, ``failed_steps`` and ``on_chunk`` still see
            every step. Use it for long runs: memory stays flat.
        dtype: ``"float64"`` (default) or ``"float32"``: the precision of the
            whole run (model, state, operators, records). In float32 the
            round-off of an assembled stiff force can exceed eq. 51's bound at
            the default ``tol_r = 1e-5``; see README "Precision".

    Everything is validated before anything is traced.
    """
    validate_scheme(scheme)
    validate_model(model)
    h = _check_finite_positive("h", h)
    t0 = float(t0)
    t1 = float(t1)
    if not (math.isfinite(t0) and math.isfinite(t1)) or t1 <= t0:
        raise ConfigError(f"t1 must be finite and greater than t0, got t0={t0}, t1={t1}")
    if h > t1 - t0:
        raise ConfigError(f"h must be in (0, t1 - t0] = (0, {t1 - t0}], got {h}")
    q0 = np.asarray(q0, dtype=float).reshape(-1) if np.ndim(q0) else np.asarray([q0], float)
    v0 = np.asarray(v0, dtype=float).reshape(-1) if np.ndim(v0) else np.asarray([v0], float)
    validate_initial_state(model, q0, v0)
    for name, value in (("record_every", record_every), ("chunk_size", chunk_size or 1)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ConfigError(f"{name} must be an integer >= 1, got {value!r}")
    if dtype not in DTYPES:
        raise ConfigError(f"dtype must be one of {', '.join(map(repr, DTYPES))}, got {dtype!r}")
    with precision(dtype):
        sol, error = _integrate(*_cast((model, scheme), dtype), t0, t1, h, q0.astype(dtype), v0.astype(dtype),
                                throw=throw, chunk_size=chunk_size, progress=progress, on_chunk=on_chunk,
                                record_every=record_every, dtype=dtype)
    if observe is not None:  # in float64, from the (possibly float32) states
        sol.observables = {k: np.asarray(v) for k, v in observe(_float64_view(sol)).items()}
    if error is not None:
        error.solution = sol
        raise error
    return sol


DTYPES = ("float64", "float32")


@contextlib.contextmanager
def precision(dtype: str):
    """Run the enclosed JAX code in ``dtype`` ("float64" or "float32").

    float32 turns ``jax_enable_x64`` off for the enclosed code and clears JAX's
    caches on entry and on exit: JAX caches the constants a traced function
    closes over (NumPy arrays) without their precision, so a function traced in
    one precision would otherwise be lowered with the other's constants. A
    float32 run therefore compiles afresh each time.
    """
    if dtype == "float64" and jax.config.jax_enable_x64:
        yield
        return
    jax.clear_caches()
    try:
        with jax.enable_x64(dtype == "float64"):
            yield
    finally:
        jax.clear_caches()


def _cast(tree, dtype: str):
    """Every floating-point leaf of ``tree`` (arrays and NumPy scalars) as ``dtype``."""

    def cast(x):
        return jnp.asarray(x, dtype) if eqx.is_inexact_array(x) or isinstance(x, np.floating) else x

    return jax.tree_util.tree_map(cast, tree)


def _float64_view(sol: Solution) -> Solution:
    """``sol`` with its floating-point arrays in float64 (itself if they are)."""
    if sol.q.dtype == np.float64:
        return sol

    def up(x):
        x = np.asarray(x)
        return x.astype(np.float64) if np.issubdtype(x.dtype, np.floating) else x

    return dataclasses.replace(sol, ts=up(sol.ts), q=up(sol.q), v=up(sol.v),
                               records=jax.tree_util.tree_map(up, sol.records))


def _integrate(model, scheme, t0, t1, h, q0, v0, *, throw, chunk_size, progress, on_chunk,
               record_every, dtype) -> tuple[Solution, ConvergenceError | None]:
    """The time loop of :func:`simulate` on validated arguments, in the precision
    already set by the caller; returns the solution and, when ``throw`` and a
    step failed, the error to raise."""
    n_steps = _n_steps(t0, t1, h)
    length = chunk_size or chunk_length(model)
    n_chunks = -(-n_steps // length)

    args0 = (model, scheme, jnp.asarray(t0), jnp.asarray(q0), jnp.asarray(v0), jnp.asarray(h))
    tc = time.perf_counter()
    prep = _prepare_and_init.lower(*args0).compile()
    compile_time = time.perf_counter() - tc

    tw = time.perf_counter()
    ops, state = prep(*args0)
    jax.block_until_ready(state)
    wall = time.perf_counter() - tw

    carry = (state, jnp.zeros((), jnp.int32), jnp.zeros((), bool))
    template = output_template(model, state.q.dtype)
    consts = (jnp.asarray(h), jnp.asarray(n_steps), jnp.asarray(throw))
    tc = time.perf_counter()
    run = _run_chunk_jit.lower(model, scheme, ops, carry, *consts, length).compile()
    compile_time += time.perf_counter() - tc

    chunks = []
    totals = RunTotals()
    first_failure = None
    steps_done = 0
    for k in range(n_chunks):
        tw = time.perf_counter()
        carry, (packed, done) = run(model, scheme, ops, carry, *consts, length)
        jax.block_until_ready((carry, packed, done))
        wall += time.perf_counter() - tw
        packed, done = jax.device_get((packed, done))
        out = jax.tree_util.tree_map(lambda x: x[done], unpack_outputs(*packed, template))
        if on_chunk is not None:
            on_chunk(k, out)
        first = steps_done + 1
        totals.add(out, first_step=first)
        steps_done += len(out.t)
        bad = np.nonzero(out.result != Result.successful)[0]
        if first_failure is None and bad.size:
            i = int(bad[0])
            first_failure = (first + i, out, i)
        stop = throw and first_failure is not None
        last = stop or k + 1 == n_chunks
        chunks.append(_every(out, first, record_every, keep_last=last))
        if progress:
            print(f"\r  step {steps_done}/{n_steps} ({100.0 * steps_done / n_steps:5.1f} %)",
                  end="" if not last else "\n", file=sys.stderr, flush=True)
        if stop:
            break

    records = _prepend_initial(model, chunks, t0, q0, v0)
    sol = Solution(
        ts=np.asarray(records.t),
        q=np.asarray(records.q),
        v=np.asarray(records.v),
        records=records,
        h=h,
        n_steps=steps_done,
        n_steps_requested=n_steps,
        result=Result.successful if first_failure is None else Result(int(first_failure[1].result[first_failure[2]])),
        wall_time=wall,
        compile_time=compile_time,
        totals=totals,
    )
    if not (throw and first_failure is not None):
        return sol, None
    step, out, i = first_failure
    result = Result(int(out.result[i]))
    if result.subproblem in SUBPROBLEMS:
        j = SUBPROBLEMS.index(result.subproblem)
    else:  # a coupled iteration: report its worst residual
        j = int(np.argmax(out.residual[i] / np.maximum(out.tolerance[i], 1e-300)))
    err = ConvergenceError(
        step=step,
        time=float(out.t[i]),
        result=result,
        residual=float(out.residual[i, j]),
        tolerance=float(out.tolerance[i, j]),
        hint=(FLOAT32_HINT if dtype == "float32" and result in CAPPED
              else nonfinite_origin(ops, state) if result in NONFINITE else ""),
    )
    return sol, err


CAPPED = (Result.smooth_max_iter, Result.position_max_iter, Result.velocity_max_iter, Result.coupled_max_iter)
FLOAT32_HINT = (
    "The run is in float32 (eps = 1.2e-7): if the residual is within a few hundred eps of the size of "
    "its terms, the limit is the precision; rerun in float64."
)
NONFINITE = (Result.smooth_nonfinite, Result.position_nonfinite, Result.velocity_nonfinite)

OPERATOR_NAMES = {
    "M": "the mass matrix", "K": "the stiffness matrix", "C": "the damping matrix",
    "G": "the constraint Jacobian",
    "smooth_inv": "the inverted iteration matrix of the smooth motion sub-problem",
    "position_inv": "the inverted iteration matrix of the position correction",
    "velocity_inv": "the inverted iteration matrix of the velocity jump",
}


def nonfinite_origin(ops: Operators, initial: StepState) -> str:
    """Why a run met a non-finite value, when it was there before the first
    step: a constant operator computed once for the step size (an inverted
    iteration matrix is not finite when the matrix is singular), or the
    initial acceleration (M(q0) singular, or f(q0, v0, t0) not finite).
    Checked on the host only after a failure, so it costs a run nothing.
    Returns ``""`` when both are finite."""

    def finite(tree) -> bool:
        return all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree_util.tree_leaves(tree))

    bad = [OPERATOR_NAMES[f.name] for f in dataclasses.fields(ops)
           if f.name in OPERATOR_NAMES and getattr(ops, f.name) is not None and not finite(getattr(ops, f.name))]
    causes = []
    if bad:
        listed = bad[0] if len(bad) == 1 else ", ".join(bad[:-1]) + " and " + bad[-1]
        causes.append(f"{listed} (computed once for this h) {'is' if len(bad) == 1 else 'are'} not finite: "
                      "a singular matrix (a coordinate with neither mass nor stiffness?)")
    if not finite(initial.vd):
        causes.append("the initial acceleration is not finite (M(q0) singular, or f(q0, v0, t0) not finite)")
    return ("Before the first step, " + "; ".join(causes) + ".") if causes else ""


def _every(records: StepOutput, first_step: int, k: int, keep_last: bool) -> StepOutput:
    """The records of the steps whose number is a multiple of ``k`` (and the
    chunk's last step if ``keep_last``); the chunk starts at step ``first_step``."""
    if k == 1:
        return records
    numbers = first_step + np.arange(len(records.t))
    keep = numbers % k == 0
    if keep_last and len(keep):
        keep[-1] = True
    return jax.tree_util.tree_map(lambda x: x[keep], records)


def _prepend_initial(model: Model, chunks: list[StepOutput], t0, q0, v0) -> StepOutput:
    """Concatenate the chunks after a zero record holding the initial state."""
    first = chunks[0]
    init = jax.tree_util.tree_map(lambda x: np.zeros((1,) + x.shape[1:], x.dtype), first)
    gap = np.asarray(model.unilateral(jnp.asarray(q0)))
    bil = np.asarray(model.bilateral(jnp.asarray(q0)))
    init = eqx.tree_at(
        lambda r: (r.t, r.q, r.v, r.gap, r.bilateral),
        init,
        (np.array([t0]), q0[None], v0[None], gap[None], bil[None]),
    )
    return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs, axis=0), init, *chunks)
