"""Result codes carried through the compiled loop, and the errors raised at the boundary.

Inside ``jit`` a failure is a value (an ``int8`` code per step); the boundary
turns the first failure into a :class:`ConvergenceError` that names the step,
the time, the sub-problem and the residual, unless the caller asked not to throw.
"""

from __future__ import annotations

import enum
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .solution import Solution

SUBPROBLEMS = ("smooth motion", "position correction", "velocity jump")
COUPLED = "coupled iteration"


class Result(enum.IntEnum):
    successful = 0
    smooth_max_iter = 1
    position_max_iter = 2
    velocity_max_iter = 3
    smooth_nonfinite = 4
    position_nonfinite = 5
    velocity_nonfinite = 6
    coupled_max_iter = 7
    coupled_diverged = 8

    @property
    def subproblem(self) -> str | None:
        if self is Result.successful:
            return None
        if int(self) >= 7:
            return COUPLED
        return SUBPROBLEMS[(int(self) - 1) % 3]

    @property
    def message(self) -> str:
        if self is Result.successful:
            return "successful"
        if self is Result.coupled_max_iter:
            return (
                "the coupled (CS) iteration over the three sub-problems did not converge within the "
                "iteration cap (reduce h, or raise max_iter)"
            )
        if self is Result.coupled_diverged:
            return "the coupled (CS) iteration diverged (its residual grew without bound or became non-finite)"
        if int(self) <= 3:
            return (
                f"Newton did not converge in the {self.subproblem} sub-problem within the "
                "iteration cap (raise max_iter, loosen tol_r/tol_f, or reduce h)"
            )
        return f"a non-finite value (NaN or inf) appeared in the {self.subproblem} sub-problem"


class ConfigError(ValueError):
    """Bad input: an out-of-range, non-finite or unknown field, caught before tracing."""


class ConvergenceError(RuntimeError):
    """A step failed; carries where and why, and the trajectory up to that step
    (``solution``, set by :func:`~nsga_jax.simulate`)."""

    def __init__(self, step: int, time: float, result: Result, residual: float, tolerance: float,
                 hint: str = ""):
        self.solution: Solution | None = None
        self.step = step
        self.time = time
        self.result = result
        self.residual = residual
        self.tolerance = tolerance
        super().__init__(
            f"step {step} (t = {time:.6g} s): {result.message}; "
            f"residual {residual:.3e} vs tolerance {tolerance:.3e}. "
            + (f"{hint} " if hint else "")
            + "Pass throw=False (CLI: --no-throw) to keep going and mark failed steps."
        )


class InvariantError(RuntimeError):
    """A run that a ``strict`` caller asked to fail when an invariant broke
    (energy created at an impact); carries the run's ``solution``."""

    def __init__(self, message: str, solution: Solution | None = None):
        self.solution = solution
        super().__init__(message + ". (strict: energy growth at impacts is an error; without strict it is a "
                         "warning in the run's summary)")
