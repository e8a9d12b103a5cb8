"""How long the first step of a run on the dense path takes, from the
model's structure alone, and whether to start it: checked before anything
is compiled, after the memory check (:mod:`~nsga_jax._memory`).

A run that assembles its iteration matrices factorises n × n matrices (LU,
2n³/3 floating-point operations each): a model that fits in memory can
still take minutes before its first step ends. The flexible cube at 15
divisions (12,288 coordinates) by CS factorises four such matrices in its
first step (the initial acceleration's and one a sub-problem), about
1.6·10¹² operations; a matrix-free run
(:mod:`~nsga_jax._integrators.krylov`, DS and DSn on a matrix-free model)
factorises none. :func:`first_step_factorisations` counts a first step's
factorisations from the kinds of its iteration matrices
(:func:`~nsga_jax._integrators.operators.matrix_kinds`);
:func:`estimate_first_step` turns them into seconds at the LU rate of the
machine, :func:`lu_rate` (one LU of :data:`PROBE_SIZE` timed once per process
and precision, only for a model whose estimate at :data:`LU_RATE` passes a
tenth of a second); :func:`check_first_step` refuses, with a
:class:`~nsga_jax.ConfigError` naming the estimate, a run whose first step
is estimated above its limit (:data:`LIMIT_SECONDS` by default;
``first_step_limit=None`` or ``--first-step-limit inf`` runs anyway).
Calibrated on the cube (docs/performance.md, "The first step of a dense
run", ``experiments/tools/first_step.py``).
"""

from __future__ import annotations

import functools
import numbers
import time
from typing import TYPE_CHECKING, NamedTuple

from ._results import ConfigError

if TYPE_CHECKING:
    from ._integrators.base import AbstractScheme
    from ._models.base import Model

LIMIT_SECONDS = 60.0
"""A first step estimated above this many seconds is refused by default."""

NOTE_SECONDS = 5.0
"""A first step estimated above this many seconds is announced with the
compiling line, and the run's first chunk is a single step (its progress
line comes after that step)."""

PROBE_SIZE = 2000
"""Size of the LU timed by :func:`lu_rate`."""

LU_RATE = 13e9
"""LU floating-point operations a second assumed before any is timed:
jax.scipy.linalg.lu_factor at n = 2000 in float64 measured 13·10⁹ (0.41 s)
on a 2-core AMD EPYC under load 3.9 (2026-12-03); 5·10⁹ at n = 1000,
19·10⁹ at n = 3000."""

INVERSE_LUS = 3.0
"""A constant iteration matrix inverted once per step size (LU and the
inverse formed from it: 2n³ operations) counts as three factorisations."""


class StepEstimate(NamedTuple):
    """The estimated first step of a run.

    Attributes:
        n_dof: coordinates n of the model.
        factorisations: n × n LU factorisations of the first step (a constant
            matrix's inversion counts :data:`INVERSE_LUS`); 0 on the matrix-free path.
        rate: LU operations a second of this machine (:func:`lu_rate`).
        seconds: ``factorisations * 2n³/3 / rate``.
        measured: the rate was measured on this machine (else assumed or given).
    """

    n_dof: int
    factorisations: float
    rate: float
    seconds: float
    measured: bool = False

    def describe(self) -> str:
        """``40 s for 3 LU factorisations of 12,288 x 12,288``."""
        from ._progress import duration

        count = f"{self.factorisations:g} LU factorisation{'s' if self.factorisations != 1 else ''}"
        return f"{duration(self.seconds)} for {count} of {self.n_dof:,} x {self.n_dof:,}"


def first_step_factorisations(model: Model, scheme: AbstractScheme) -> float:
    """Dense LU factorisations of a first step of ``model`` by ``scheme``, at least.

    From the kinds of the iteration matrices the step solves with (static
    structure only, nothing evaluated): a constant one is inverted once per
    step size (:data:`INVERSE_LUS`; a block-tridiagonal one costs O(n), as
    does a system's block elimination, :mod:`~nsga_jax._integrators.structured`); a
    held one (DS and DSn in large models) is factorised at the first step's
    first iteration, a refactored one at every iteration. Counted are the
    iterations every step makes: one of the smooth motion in DS and DSn
    (their position and velocity sub-problems iterate only with active
    contacts), one of each sub-problem in a global iteration of CS, one of
    Moreau–Jean's; and the generalized-α schemes' initial acceleration, a
    dense solve with M (one more). A matrix-free run counts none.
    """
    from ._integrators.ds import AbstractGenAlpha
    from ._integrators.iteration_matrix import ConstantInverse, ConstantTridiagonal
    from ._integrators.structured import Structured
    from ._memory import assembles_nothing, present_subproblems

    kinds = [k for k, p in zip(scheme.matrix_kinds(model), present_subproblems(model, scheme)) if p]
    if assembles_nothing(kinds):
        return 0.0
    every = [True] * 3 if "smooth" not in scheme.subproblems else [True, False, False]
    every = [e for e, p in zip(every, present_subproblems(model, scheme)) if p]
    count = float(isinstance(scheme, AbstractGenAlpha))
    for kind, iterates in zip(kinds, every):
        if issubclass(kind, ConstantInverse):
            count += INVERSE_LUS
        elif not issubclass(kind, (ConstantTridiagonal, Structured)) and not kind.is_constant and iterates:
            count += 1.0
    return count


@functools.lru_cache(maxsize=None)
def lu_rate(dtype: str = "float64", size: int = PROBE_SIZE) -> float:
    """LU operations a second on the default device: one ``lu_factor`` of
    ``size`` × ``size`` in ``dtype`` timed after its compilation (the faster
    of two), once per process."""
    import jax
    import jax.numpy as jnp
    import numpy as np
    from jax.scipy.linalg import lu_factor

    with jax.ensure_compile_time_eval():  # timed for real, also when asked inside a trace (integrate under jit)
        a = jnp.asarray(np.eye(size) * size + np.random.default_rng(0).standard_normal((size, size)), dtype)
        factor = jax.jit(lu_factor)
        jax.block_until_ready(factor(a))
        best = float("inf")
        for _ in range(2):
            started = time.perf_counter()
            jax.block_until_ready(factor(a))
            best = min(best, time.perf_counter() - started)
    return 2.0 * size**3 / 3.0 / best


def estimate_first_step(model: Model, scheme: AbstractScheme, dtype: str = "float64",
                        rate: float | None = None, members: int = 1) -> StepEstimate:
    """The first step's factorisations and seconds, of ``members`` runs
    stepped together (a batch: one device factorises each member's
    matrices); ``rate`` [operations/s] defaults to :data:`LU_RATE`, or to
    :func:`lu_rate` measured on this machine where the estimate at
    :data:`LU_RATE` passes 0.1 s."""
    n = model.n_dof
    count = first_step_factorisations(model, scheme) * members
    flops = count * 2.0 * n**3 / 3.0
    measured = rate is None and flops / LU_RATE >= 0.1
    if rate is None:
        rate = lu_rate(dtype) if measured else LU_RATE
    return StepEstimate(n, count, rate, flops / rate, measured)


def check_limit(name: str, limit: float | None) -> None:
    """Refuse a limit that is not a positive number of seconds (``inf`` and ``None``: no limit)."""
    if limit is None:
        return
    if isinstance(limit, bool) or not isinstance(limit, numbers.Real):
        raise TypeError(f"{name} must be a number of seconds, inf or None, got {type(limit).__name__} {limit!r}")
    if not limit > 0:
        raise ConfigError(f"{name} must be a positive number of seconds, inf or None, got {limit}")


def check_first_step(model: Model, scheme: AbstractScheme, dtype: str = "float64", *,
                     limit: float | None = LIMIT_SECONDS, what: str = "the model",
                     rate: float | None = None, members: int = 1) -> StepEstimate:
    """Refuse a run (or ``members`` runs stepped together) whose first step
    is estimated above ``limit`` seconds, before anything is compiled
    (``limit=None``: never). Raises :class:`~nsga_jax.ConfigError` naming the
    size, the scheme, the estimate and what to do. Returns the estimate."""
    check_limit("first_step_limit", limit)
    est = estimate_first_step(model, scheme, dtype, rate, members)
    if limit is None or est.seconds <= limit:
        return est
    source = "measured here" if est.measured else "assumed"
    krylov = ("the matrix-free path, which every scheme takes for a matrix-free model this size unless "
              "krylov_min_dof=None (it assembles nothing), or " if getattr(model, "matrix_free", False) else "")
    runs = f" ({members} members stepped together)" if members > 1 else ""
    fewer = "fewer members a batch (batch_size), " if members > 1 else ""
    raise ConfigError(
        f"{what}: the first step of {type(scheme).__name__} on {est.n_dof:,} coordinates{runs} is estimated at "
        f"{est.describe()} at {est.rate / 1e9:.3g} GFLOP/s ({source}); the limit is {limit:g} s; use "
        f"{fewer}{krylov}a smaller model (a coarser mesh, fewer divisions or elements); to run anyway, pass "
        f"first_step_limit=None (--first-step-limit inf)")


__all__ = ["INVERSE_LUS", "LIMIT_SECONDS", "LU_RATE", "NOTE_SECONDS", "PROBE_SIZE", "StepEstimate",
           "check_first_step", "check_limit", "estimate_first_step", "first_step_factorisations", "lu_rate"]


def check_run_fits(model: Model, scheme: AbstractScheme, options: dict, what: str, *, n_steps: int = 0,
                   record_every: int = 1) -> None:
    """The memory check and the first-step check of a run of ``n_steps``
    steps keeping every ``record_every``-th, with ``simulate``'s keyword
    ``options`` (``dtype``, ``check_memory``, ``first_step_limit``), ahead
    of it and with ``what`` (a scene's name) in their messages; ``simulate``
    checks again and validates the rest."""
    import numpy as np

    from ._memory import check_fits, kept_records

    dtype = options["dtype"]
    if dtype not in ("float32", "float64"):
        return
    if options.get("check_memory", True) is True:
        records, record_numbers = kept_records(model, scheme, n_steps, record_every)
        check_fits(model, scheme, np.dtype(dtype).itemsize, what=what, records=records, record_numbers=record_numbers)
    limit = options.get("first_step_limit", LIMIT_SECONDS)
    if isinstance(limit, (int, float)):
        check_first_step(model, scheme, dtype, limit=limit, what=what)
