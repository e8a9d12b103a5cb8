"""The time loop: ``simulate(model, scheme, t0, t1, h, q0, v0)``.

The whole trajectory runs in compiled ``lax.scan`` calls over chunks of steps
(one compilation, reused for every chunk); no Python runs inside a chunk. After
each chunk the host collects the chunk's records, reports progress, hands the
chunk to an optional callback (the CLI writes it to disk at once), and stops
early on a failure when ``throw=True``.

Compile time is measured apart (``lower().compile()``); ``wall_time`` is the
execution time of the constant-operator preparation, the initialisation and
all chunks (until their results are ready; copying them to NumPy is not
counted).
"""

from __future__ import annotations

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

from .integrators.base import AbstractScheme, StepOutput
from .models.base import Model
from .results import SUBPROBLEMS, ConfigError, ConvergenceError, Result

Observe = Callable[["Solution"], dict[str, np.ndarray]]

DEFAULT_CHUNK = 4096


@dataclass
class Solution:
    """A trajectory and what the scheme did to get it (NumPy arrays, host side).

    Every per-time array has a leading axis of length N + 1 (the initial state
    first). Record fields (``impulse``, ``nu``, ``lam``, ``iterations``,
    ``result``...) are zero at index 0.

    Attributes:
        ts: times [s], (N+1,).
        q, v: coordinates and velocities, (N+1, n).
        records: :class:`~nsga_jax.integrators.ds.StepOutput` with NumPy leaves, (N+1, ...).
        observables: named scene quantities, each (N+1,).
        h: step size [s]; n_steps: steps actually taken (fewer than requested
            when a failure stopped the run).
        result: the first failure's :class:`Result` (``successful`` if none).
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

    @property
    def iterations(self) -> np.ndarray:
        """Newton iterations (N+1, 3): smooth, position, velocity."""
        return np.asarray(self.records.iterations)

    @property
    def failed_steps(self) -> np.ndarray:
        """Indices (into ts) of the steps whose result is not successful."""
        return np.nonzero(np.asarray(self.records.result) != Result.successful)[0]

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
        it = self.iterations[1:]
        gap = self.gap
        stats = {
            "n_steps": int(self.n_steps),
            "h": float(self.h),
            "wall_time_s": float(self.wall_time),
            "compile_time_s": float(self.compile_time),
            "us_per_step": 1e6 * float(self.wall_time) / max(int(self.n_steps), 1),
            "iterations": {
                name: {"mean": float(it[:, i].mean()) if len(it) else 0.0,
                       "max": int(it[:, i].max()) if len(it) else 0}
                for i, name in enumerate(("smooth", "position", "velocity"))
            },
            "failed_steps": int(len(self.failed_steps)),
            "result": self.result.name,
            "max_penetration": float(max(0.0, -gap.min())) if gap.size else 0.0,
            "max_bilateral_violation_position": _absmax(self.records.bilateral),
            "max_bilateral_violation_velocity": _absmax(self.records.bilateral_rate),
        }
        total = it.sum(axis=1) if len(it) else np.zeros(1)
        stats["iterations"]["linear_solves"] = {"mean": float(total.mean()), "max": int(total.max())}
        return stats


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
    """``length`` steps of ``scheme`` in one scan. Steps past ``n_steps``, or after a
    failure when ``stop_on_failure``, leave the state unchanged and are marked
    not done (their records are dropped by the caller). Masking with ``where``
    rather than ``lax.cond``: on CPU a cond around the step costs more than the
    few padded steps it would save."""

    def body(carry, _):
        state, k, stopped = carry
        do = (k < n_steps) & ~stopped
        new_state, out = scheme.step(model, ops, state, h)
        state = jax.tree_util.tree_map(lambda a, b: jnp.where(do, a, b), new_state, state)
        failed = do & (out.result != Result.successful)
        return (state, k + do.astype(k.dtype), stopped | (failed & stop_on_failure)), (out, do)

    return lax.scan(body, carry, None, length=length)


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
        chunk_size: steps per compiled scan (default: about a twentieth of the
            run, between 256 and 4096 steps; every chunk reuses one compilation).
        progress: print progress on stderr after each chunk.
        on_chunk: called as ``on_chunk(k, partial)`` after chunk k with that
            chunk's records (a :class:`Solution` of the chunk alone).
        observe: computes named observables from the finished solution.

    Everything is validated before anything is traced.
    """
    validate_scheme(scheme)
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

    n_steps = _n_steps(t0, t1, h)
    if chunk_size:
        n_chunks = -(-n_steps // chunk_size)
    else:  # about 20 progress reports, chunks of 256 to 4096 steps
        n_chunks = max(-(-n_steps // DEFAULT_CHUNK), min(20, -(-n_steps // 256)))
    length = -(-n_steps // n_chunks)  # equal chunks: fewer than n_chunks padded steps

    args0 = (model, scheme, jnp.asarray(t0), jnp.asarray(q0), jnp.asarray(v0), jnp.asarray(h))
    tc = time.perf_counter()
    prep = _prepare_and_init.lower(*args0).compile()
    compile_time = time.perf_counter() - tc

    tw = time.perf_counter()
    ops, state = prep(*args0)
    jax.block_until_ready(state)
    wall = time.perf_counter() - tw

    carry = (state, jnp.zeros((), jnp.int32), jnp.zeros((), bool))
    consts = (jnp.asarray(h), jnp.asarray(n_steps), jnp.asarray(throw))
    tc = time.perf_counter()
    run = _run_chunk_jit.lower(model, scheme, ops, carry, *consts, length).compile()
    compile_time += time.perf_counter() - tc

    chunks = []
    first_failure = None
    for k in range(n_chunks):
        tw = time.perf_counter()
        carry, (out, done) = run(model, scheme, ops, carry, *consts, length)
        jax.block_until_ready((carry, out, done))
        wall += time.perf_counter() - tw
        out, done = jax.device_get((out, done))
        out = jax.tree_util.tree_map(lambda x: x[done], out)
        chunks.append(out)
        if on_chunk is not None:
            on_chunk(k, out)
        steps_done = sum(len(c.t) for c in chunks)
        if progress:
            print(f"\r  step {steps_done}/{n_steps} ({100.0 * steps_done / n_steps:5.1f} %)",
                  end="" if k + 1 < n_chunks else "\n", file=sys.stderr, flush=True)
        bad = np.nonzero(out.result != Result.successful)[0]
        if first_failure is None and bad.size:
            i = int(bad[0])
            first_failure = (steps_done - len(out.t) + i + 1, out, i)
        if throw and first_failure is not None:
            if progress:
                print(file=sys.stderr)
            break

    records = _prepend_initial(model, chunks, t0, q0, v0)
    sol = Solution(
        ts=np.asarray(records.t),
        q=np.asarray(records.q),
        v=np.asarray(records.v),
        records=records,
        h=h,
        n_steps=len(records.t) - 1,
        n_steps_requested=n_steps,
        result=Result.successful if first_failure is None else Result(int(first_failure[1].result[first_failure[2]])),
        wall_time=wall,
        compile_time=compile_time,
    )
    if observe is not None:
        sol.observables = {k: np.asarray(v) for k, v in observe(sol).items()}
    if throw and first_failure is not None:
        step, out, i = first_failure
        result = Result(int(out.result[i]))
        if result.subproblem in SUBPROBLEMS:
            j = SUBPROBLEMS.index(result.subproblem)
        else:  # a coupled iteration: report its worst residual
            j = int(np.argmax(out.residual[i] / np.maximum(out.tolerance[i], 1e-300)))
        err = ConvergenceError(
            step=step,
            time=float(out.t[i]),
            result=Result(int(out.result[i])),
            residual=float(out.residual[i, j]),
            tolerance=float(out.tolerance[i, j]),
        )
        err.solution = sol
        raise err
    return sol


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
