"""Results of a step, and the errors raised at the boundary.

One vocabulary of outcomes, :data:`FAILURES`: a named member per failure
(each sub-problem's iteration cap, a non-finite value in a sub-problem, the
coupled scheme's cap and divergence), each with its message. It gives

- :data:`RESULTS`, an enumeration built on ``optimistix.RESULTS`` (an
  ``equinox`` enumeration: ``RESULTS.where``, ``RESULTS.promote``,
  ``result.error_if``) that compiled code carries: a scheme combines its
  sub-problems' results with ``RESULTS.where``, never by arithmetic on codes,
  and a step's record stores the member's integer code;
- :data:`Result`, the same members with the same codes as a Python
  ``IntEnum`` (:class:`HostResult`), for the host: a stored code (or a NumPy
  array of them) compares with ``Result.position_max_iter``, and
  ``Result(code)`` decodes one to its name, message and sub-problem.

The boundary turns the first failure into a :class:`ConvergenceError` that
names the step, the time, the sub-problem and the residual, unless the caller
asked not to throw.

``RESULTS`` and ``Result`` load JAX (optimistix) on first use; the errors do
not, so that the command line answers ``--help`` and input errors at once.
"""

from __future__ import annotations

import enum
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ._solution import Solution

SUBPROBLEM_LABELS = {
    "smooth": "smooth motion",
    "position": "position correction",
    "velocity": "velocity jump",
    "moreau_jean": "Moreau–Jean (velocity-level)",
    "coupled": "coupled (CS) iteration",
}
"""The sub-problems schemes declare (``scheme.subproblems``), and what messages and plots call them."""


def _capped(sub: str) -> str:
    return (f"Newton did not converge in the {SUBPROBLEM_LABELS[sub]} sub-problem within the iteration cap "
            "(raise max_iter, loosen tol_r/tol_f, or reduce h)")


def _nonfinite(sub: str) -> str:
    return f"a non-finite value (NaN or inf) appeared in the {SUBPROBLEM_LABELS[sub]} sub-problem"


NEWTON_SUBPROBLEMS = ("smooth", "position", "velocity", "moreau_jean")
"""The sub-problems solved by a Newton loop of their own (each has a cap and a non-finite member)."""

FAILURES: dict[str, str] = {
    **{f"{sub}_max_iter": _capped(sub) for sub in NEWTON_SUBPROBLEMS},
    **{f"{sub}_nonfinite": _nonfinite(sub) for sub in NEWTON_SUBPROBLEMS},
    "coupled_max_iter": ("the coupled (CS) iteration over the three sub-problems did not converge within the "
                         "iteration cap (reduce h, or raise max_iter)"),
    "coupled_diverged": ("the coupled (CS) iteration diverged (its residual grew without bound or became "
                         "non-finite)"),
}
"""Each failure's name and message: the members :data:`RESULTS` adds to ``optimistix.RESULTS``."""

FAILURE_SUBPROBLEM = {name: name.removesuffix("_max_iter").removesuffix("_nonfinite").removesuffix("_diverged")
                      for name in FAILURES}
"""The sub-problem (a key of :data:`SUBPROBLEM_LABELS`) each failure happened in."""


class HostResult(enum.IntEnum):
    """A result decoded on the host: the members of :data:`RESULTS` with their
    codes (``Result(code)``), names, messages and sub-problems. Subclassed
    once, as :data:`Result`, when :data:`RESULTS` is built."""

    @property
    def message(self) -> str:
        if self.name == "successful":
            return "successful"
        return FAILURES.get(self.name) or _enumeration()[getattr(_enumeration(), self.name)]

    @property
    def subproblem(self) -> str | None:
        """The sub-problem it happened in (a key of :data:`SUBPROBLEM_LABELS`), or ``None``."""
        return FAILURE_SUBPROBLEM.get(self.name)

    @property
    def capped(self) -> bool:
        """Whether an iteration cap stopped the sub-problem."""
        return self.name.endswith("_max_iter")

    @property
    def nonfinite(self) -> bool:
        """Whether a NaN or inf appeared in the sub-problem."""
        return self.name.endswith("_nonfinite")


def _build() -> tuple[Any, Any]:
    """:data:`RESULTS` (``optimistix.RESULTS`` and a member per entry of
    :data:`FAILURES`) and :data:`Result` (its members and codes as a :class:`HostResult`)."""
    import optimistix as optx

    from ._compat import extend_enumeration

    enumeration = extend_enumeration(optx.RESULTS, "RESULTS", FAILURES, __name__,
                                     "Results of a step inside compiled code: ``optimistix.RESULTS`` and a member "
                                     "per failure (:data:`nsga_jax._results.FAILURES`).")
    codes = {name: int(code_of(getattr(enumeration, name))) for name in enumeration._name_to_item}
    make: Any = HostResult  # the functional Enum API: a subclass with these members
    return enumeration, make("Result", codes, module=__name__)


def code_of(result) -> Any:
    """The integer code (int32 array) a record stores for a :data:`RESULTS` member (traced or not)."""
    import jax

    (code,) = jax.tree_util.tree_leaves(result)
    return code


def from_code(code) -> Any:
    """The :data:`RESULTS` member of a stored code (traced or not; under ``jit``
    its message is chosen at run time by ``error_if``)."""
    import jax
    import jax.numpy as jnp

    structure = jax.tree_util.tree_structure(_enumeration().successful)
    return jax.tree_util.tree_unflatten(structure, [jnp.asarray(code, jnp.int32)])


if TYPE_CHECKING:
    RESULTS: Any
    """The enumeration compiled code carries (see the module)."""
    Result: Any
    """The same members and codes on the host, a :class:`HostResult` subclass."""


def _enumeration() -> Any:
    return __getattr__("RESULTS")


def __getattr__(name: str):  # PEP 562: the enumeration is built (and JAX loaded) on first use
    if name in ("RESULTS", "Result"):
        if "RESULTS" not in globals():
            globals().update(zip(("RESULTS", "Result"), _build()))
        return globals()[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class ConfigError(ValueError):
    """Bad input: an out-of-range, non-finite or unknown field, caught before tracing."""


class ConvergenceError(RuntimeError):
    """A step failed; carries where and why, and the trajectory up to that step
    (``solution``, set by :func:`~nsga_jax.simulate`).

    Attributes:
        step, time: the failed step's number and end time [s].
        result: its :data:`Result` (``.name``, ``.message``, ``.subproblem``).
        subproblem: the sub-problem it happened in (a key of :data:`SUBPROBLEM_LABELS`).
        residual, tolerance: that sub-problem's final residual norm and bound (eq. 51).
    """

    def __init__(self, step: int, time: float, result: HostResult, residual: float, tolerance: float,
                 hint: str = ""):
        self.solution: Solution | None = None
        self.step = step
        self.time = time
        self.result = result
        self.subproblem = result.subproblem
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
