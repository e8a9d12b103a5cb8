"""The :class:`Solution` of a run: its trajectory, records, result and statistics.

One type for every way of running: :func:`~nsga_jax.integrate` (pure, JAX
leaves, usable under ``jit``, ``grad``, ``vmap`` and sharding) and the host
drivers :func:`~nsga_jax.simulate` and :func:`~nsga_jax.simulate_batch`
(NumPy leaves, with timings, warnings and named observables).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._integrators.records import SubproblemRecord
from ._monitors import RunTotals
from ._results import HostResult, Result

Observables = Callable[["Solution"], dict[str, Any]]
"""``Solution -> {name: array (rows,)}``: named quantities of a finished run
(a scene's observables)."""


class Solution(eqx.Module):
    """A trajectory and what the scheme did to get it.

    Every per-time array has a leading axis of one row per kept step (the
    initial state first): N + 1 rows, or with ``SaveAt(every=k)``, one per k
    steps plus the initial and the last step. Record fields (``impulse``,
    ``nu``, ``lam``, ``newton``, ``result``...) are zero in the initial
    row. ``stats``, ``failed_steps`` and ``result`` always cover every step.

    Attributes:
        ts: times [s], (rows,).
        q, v: coordinates and velocities, (rows, n); (0, n) when
            ``SaveAt.fn`` chose what to keep.
        records: the stacked :class:`~nsga_jax.StepOutput` of the kept rows,
            or what ``SaveAt.fn`` returned for them.
        result: the code of the first failed step's result (``successful``'s
            if none), from every driver: ``Result(int(sol.result))`` names
            it. The host drivers return it decoded, as the
            :data:`~nsga_jax._results.Result` member (an ``IntEnum``: the code
            itself); :func:`~nsga_jax.integrate` as an int32 JAX scalar
            (:func:`~nsga_jax._results.from_code` gives the
            :data:`~nsga_jax.RESULTS` member under ``jit``).
        stats: statistics over every step (:func:`host_stats`,
            :func:`traced_stats`): Newton iterations per sub-problem, failed
            steps, constraint violations; from the host drivers also the
            timings, the energy monitors and the warnings.
        h: step size [s].
        n_steps: steps taken (fewer than requested when a failure stopped a
            host run); ``n_steps_requested``: steps asked for.
        failed_steps: step numbers k (t = t0 + k h) of the failed steps, (F,)
            (host drivers; ``None`` from :func:`~nsga_jax.integrate`, whose
            ``records.result`` or ``stats["failed_steps"]`` tell instead).
        observables: named quantities of the finished run (host drivers).
        wall_time, compile_time: execution and compilation time [s] (host).
        compile_source: ``"compiled"``, ``"cache"`` or ``"traced"`` (pure).
        warnings: the monitors' warnings (host).
    """

    ts: Any
    q: Any
    v: Any
    records: Any
    result: Any
    stats: dict[str, Any]
    h: Any
    n_steps: int = eqx.field(static=True)
    n_steps_requested: int = eqx.field(static=True)
    failed_steps: Any = None
    observables: dict[str, Any] = eqx.field(default_factory=dict)
    wall_time: float = eqx.field(default=0.0, static=True)
    compile_time: float = eqx.field(default=0.0, static=True)
    compile_source: str = eqx.field(default="traced", static=True)
    warnings: list[str] = eqx.field(default_factory=list)

    @property
    def subproblems(self) -> tuple[str, ...]:
        """The scheme's sub-problems, in the order of :attr:`iterations`' columns
        (DS, DSn: smooth, position, velocity; CS: coupled; MJ: moreau_jean)."""
        return tuple(self.records.newton.names)

    @property
    def iterations(self) -> Any:
        """Newton iterations (linear solves) per step, (rows, k): one column per
        sub-problem in the order of :attr:`subproblems` (DS: smooth, position, velocity)."""
        return self.records.newton.iterations

    def newton(self, subproblem: str) -> SubproblemRecord:
        """One sub-problem's iterations, final residuals and bounds, each (rows,),
        by its name (``sol.newton("position").iterations``)."""
        return self.records.newton[subproblem]

    @property
    def impulse(self) -> Any:
        """Constraint impulses Λ [N s], (rows, nc), bilaterals first."""
        return self.records.impulse

    @property
    def gap(self) -> Any:
        """Unilateral gaps g^U(q) [m], (rows, nu)."""
        return self.records.gap

    @property
    def failed(self) -> Any:
        """Whether any step failed (Newton cap or non-finite value)."""
        return self.stats["failed_steps"] > 0


# ------------------------------------------------------------ statistics


def host_stats(totals: RunTotals, *, n_steps: int, h: float, result: HostResult, wall_time: float = 0.0,
               compile_time: float = 0.0, compile_source: str = "compiled",
               warnings: list[str] | None = None) -> dict[str, Any]:
    """A host run's ``Solution.stats`` from its running totals (Python numbers)."""
    stats: dict[str, Any] = {
        "n_steps": int(n_steps),
        "h": float(h),
        "wall_time_s": float(wall_time),
        "compile_time_s": float(compile_time),
        "compile_source": compile_source,
        "us_per_step": 1e6 * float(wall_time) / max(int(n_steps), 1),
        "iterations": totals.iteration_stats(),
        "failed_steps": len(totals.failed),
        "impacts_at_instants": totals.instants,
        "instant_fallbacks": totals.fallbacks,
        "result": result.name,
        "max_penetration": float(max(0.0, -totals.min_gap)),
        "max_bilateral_violation_position": float(totals.max_bilateral),
        "max_bilateral_violation_velocity": float(totals.max_bilateral_rate),
    }
    stats["energy"] = totals.energy_stats()
    stats["warnings"] = list(warnings or [])
    return stats


def traced_stats(subproblems: tuple[str, ...], iterations: jax.Array, result: jax.Array, gap: jax.Array,
                 bilateral: jax.Array, bilateral_rate: jax.Array, instants: jax.Array,
                 fallback: jax.Array) -> dict[str, Any]:
    """``Solution.stats`` of :func:`~nsga_jax.integrate`, in JAX, from every
    step's iterations (N, k) of the scheme's ``subproblems``, result codes
    (N,), gaps (N, nu) [m], bilateral violations (N, nb) [m] and [m/s] and
    impacts resolved at their instants and fall-backs (N,) per step: the
    keys of :func:`host_stats` that need no host (no timings, energies or
    warnings)."""
    solves = jnp.sum(iterations, axis=1)
    real = jnp.result_type(gap, float)  # the run's precision
    stats: dict[str, Any] = {
        "iterations": {
            name: {"mean": jnp.mean(iterations[:, i], dtype=real), "max": jnp.max(iterations[:, i])}
            for i, name in enumerate(subproblems)
        },
        "failed_steps": jnp.sum(result != int(Result.successful)),
        "impacts_at_instants": jnp.sum(instants),
        "instant_fallbacks": jnp.sum(fallback),
        "max_penetration": jnp.maximum(0.0, -jnp.min(gap, initial=jnp.inf)),
        "max_bilateral_violation_position": jnp.max(jnp.abs(bilateral), initial=0.0),
        "max_bilateral_violation_velocity": jnp.max(jnp.abs(bilateral_rate), initial=0.0),
    }
    stats["iterations"]["linear_solves"] = {"mean": jnp.mean(solves, dtype=real), "max": jnp.max(solves)}
    return stats


def first_failed_code(result: jax.Array) -> jax.Array:
    """The result code of the first failed step in ``result`` (N,), or
    ``successful``'s (JAX)."""
    bad = result != int(Result.successful)
    return jnp.where(jnp.any(bad), result[jnp.argmax(bad)], jnp.asarray(int(Result.successful), result.dtype))


# ------------------------------------------------------------ host solutions


def host_solution(records, *, ts: np.ndarray, h: float, n_steps: int, n_steps_requested: int, result: HostResult,
                  totals: RunTotals | None = None, wall_time: float = 0.0, compile_time: float = 0.0,
                  compile_source: str = "compiled", warnings: list[str] | None = None) -> Solution:
    """A host driver's :class:`Solution` from its NumPy records (initial row
    first) and its running ``totals`` (without them, the records hold every
    step and give the statistics)."""
    if totals is None:
        totals = RunTotals()
        totals.add(jax.tree_util.tree_map(lambda x: np.asarray(x)[1:], records), first_step=1)
    stats = host_stats(totals, n_steps=n_steps, h=h, result=result, wall_time=wall_time, compile_time=compile_time,
                       compile_source=compile_source, warnings=warnings or [])
    return Solution(ts=np.asarray(ts), q=np.asarray(records.q), v=np.asarray(records.v), records=records,
                    result=result, stats=stats, h=h, n_steps=n_steps, n_steps_requested=n_steps_requested,
                    failed_steps=np.asarray(totals.failed, dtype=int), wall_time=wall_time,
                    compile_time=compile_time, compile_source=compile_source, warnings=list(warnings or []))


def with_observables(sol: Solution, observables: Observables | None) -> Solution:
    """``sol`` with the named quantities ``observables`` computes from it (in
    float64, from the possibly float32 states)."""
    if observables is None:
        return sol
    values = {k: np.asarray(v) for k, v in observables(float64_view(sol)).items()}
    return dataclasses.replace(sol, observables=values)


def float64_view(sol: Solution) -> Solution:
    """``sol`` with its floating-point arrays in float64 (itself if they are)."""
    if np.asarray(sol.q).dtype == np.float64:
        return sol

    def up(x):
        x = np.asarray(x)
        return x.astype(np.float64) if np.issubdtype(x.dtype, np.floating) else x

    return dataclasses.replace(sol, ts=up(sol.ts), q=up(sol.q), v=up(sol.v),
                               records=jax.tree_util.tree_map(up, sol.records))
