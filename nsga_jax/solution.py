"""The :class:`Solution` of a run: its trajectory, records and statistics (host side)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import jax
import numpy as np

from .integrators.records import StepOutput, SubproblemRecord
from .monitors import RunTotals
from .results import HostResult

Observe = Callable[["Solution"], dict[str, np.ndarray]]



@dataclass
class Solution:
    """A trajectory and what the scheme did to get it (NumPy arrays, host side).

    Every per-time array has a leading axis of length N + 1 (the initial state
    first), or, with ``record_every = k > 1``, one entry per k steps plus the
    initial and the last step. Record fields (``impulse``, ``nu``, ``lam``,
    ``newton``, ``result``...) are zero at index 0. ``stats`` and
    ``failed_steps`` always cover every step.

    Attributes:
        ts: times [s], (N+1,).
        q, v: coordinates and velocities, (N+1, n).
        records: :class:`~nsga_jax.integrators.records.StepOutput` with NumPy leaves, (N+1, ...).
        observables: named scene quantities, each (N+1,).
        h: step size [s]; n_steps: steps actually taken (fewer than requested
            when a failure stopped the run).
        result: the first failure's :data:`~nsga_jax.results.Result` (``successful`` if none).
        totals: statistics over every step (accumulated while running; computed
            from ``records`` when not given).
        stats: iteration statistics (per sub-problem name), failures, constraint
            violations, timings.
    """

    ts: np.ndarray
    q: np.ndarray
    v: np.ndarray
    records: StepOutput
    h: float
    n_steps: int
    n_steps_requested: int
    result: HostResult
    wall_time: float
    compile_time: float
    observables: dict[str, np.ndarray] = field(default_factory=dict)
    totals: RunTotals | None = None
    warnings: list[str] = field(default_factory=list)
    compile_source: str = "compiled"

    def __post_init__(self):
        if self.totals is None:
            self.totals = RunTotals()
            self.totals.add(jax.tree_util.tree_map(lambda x: np.asarray(x)[1:], self.records), first_step=1)

    @property
    def subproblems(self) -> tuple[str, ...]:
        """The scheme's sub-problems, in the order of :attr:`iterations`' columns
        (DS, DSn: smooth, position, velocity; CS: coupled; MJ: moreau_jean)."""
        return tuple(self.records.newton.names)

    @property
    def iterations(self) -> np.ndarray:
        """Newton iterations (linear solves) per step, (N+1, k): one column per
        sub-problem in the order of :attr:`subproblems` (DS: smooth, position, velocity)."""
        return np.asarray(self.records.newton.iterations)

    def newton(self, subproblem: str) -> SubproblemRecord:
        """One sub-problem's iterations, final residuals and bounds, each (N+1,),
        by its name (``sol.newton("position").iterations``)."""
        return self.records.newton[subproblem]

    @property
    def failed_steps(self) -> np.ndarray:
        """Step numbers k (t = t0 + k h) of the steps whose result is not
        successful; indices into ``ts`` when every step is recorded."""
        assert self.totals is not None  # set by __post_init__
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
        assert tot is not None  # set by __post_init__
        stats: dict[str, Any] = {
            "n_steps": int(self.n_steps),
            "h": float(self.h),
            "wall_time_s": float(self.wall_time),
            "compile_time_s": float(self.compile_time),
            "compile_source": self.compile_source,
            "us_per_step": 1e6 * float(self.wall_time) / max(int(self.n_steps), 1),
            "iterations": tot.iteration_stats(),
            "failed_steps": len(tot.failed),
            "result": self.result.name,
            "max_penetration": float(max(0.0, -tot.min_gap)),
            "max_bilateral_violation_position": float(tot.max_bilateral),
            "max_bilateral_violation_velocity": float(tot.max_bilateral_rate),
        }
        stats["energy"] = tot.energy_stats()
        stats["warnings"] = list(self.warnings)
        return stats


def _float64_view(sol: Solution) -> Solution:
    """``sol`` with its floating-point arrays in float64 (itself if they are)."""
    if sol.q.dtype == np.float64:
        return sol

    def up(x):
        x = np.asarray(x)
        return x.astype(np.float64) if np.issubdtype(x.dtype, np.floating) else x

    return dataclasses.replace(sol, ts=up(sol.ts), q=up(sol.q), v=up(sol.v),
                               records=jax.tree_util.tree_map(up, sol.records))


