"""How much memory a run needs, from the model's structure alone, and
whether the machine has it: checked before anything is traced or compiled.

The iteration matrices are dense, n × n for a model of n coordinates,
except where a large matrix-free model is solved without assembling them
(:mod:`~nsga_jax._integrators.krylov`), so a run's memory grows as n²: the flexible cube at 11
divisions (5,184 coordinates) peaks at about 2.8 GB, at 40 divisions
(206,763 coordinates) one such matrix alone is 342 GB. :func:`dense_matrices`
counts the n × n arrays a scheme's run holds at its peak from the same static
structure that chooses the iteration matrices' kinds
(:func:`~nsga_jax._integrators.operators.matrix_kinds`);
:func:`estimate_run_bytes` turns the count into bytes, calibrated on measured
peaks (docs/performance.md, ``experiments/tools/memory_peak.py``);
:func:`check_fits` refuses a run whose estimate exceeds
:func:`available_memory` with a :class:`~nsga_jax.ConfigError`. Setting the
environment variable :data:`SKIP_ENV` (``NSGA_JAX_SKIP_MEMORY_CHECK=1``), or
``check_memory=False`` where an entry point takes it, skips the check.
A run that assembles nothing holds element blocks and vectors instead,
:func:`matrix_free_numbers`, linear in n.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, NamedTuple

from ._results import ConfigError

if TYPE_CHECKING:
    from ._integrators.base import AbstractScheme
    from ._models.base import Model

SKIP_ENV = "NSGA_JAX_SKIP_MEMORY_CHECK"
"""Environment variable: set to ``1`` to skip :func:`check_fits` everywhere
(the command line included)."""

OVERHEAD = 1.15
"""Measured peak over counted dense arrays: XLA's copies around the compiled
loops and LAPACK's work arrays. Fitted on the flexible cube's peaks past
:data:`RUNTIME_BYTES` at 9 to 15 divisions (3,000 to 12,288 coordinates,
where the dense arrays dominate): 1.1 to 1.2 (docs/performance.md)."""

RUNTIME_BYTES = 0.6e9
"""Resident memory of the Python process, JAX and a compiled step apart from
the dense arrays [bytes]: about the smallest cube's measured peak (0.65 GB at
192 coordinates, of which the dense arrays are 3 MB). Already in use when
the check runs, so it is not compared with the available memory."""


class Estimate(NamedTuple):
    """A run's memory estimate.

    Attributes:
        n_dof: coordinates n of the model.
        dense: dense n × n arrays held at the peak, per member (:func:`dense_matrices`).
        itemsize: bytes per number (8 for float64, 4 for float32).
        members: runs held at once (a batch's members; 1 for one run).
        dense_bytes: ``OVERHEAD * dense * n² * itemsize * members`` [bytes].
        records_bytes: the kept records [bytes].
        blocks_bytes: element blocks and vectors of a run that assembles no
            matrix (:func:`matrix_free_numbers`) [bytes].
    """

    n_dof: int
    dense: int
    itemsize: int
    members: int
    dense_bytes: int
    records_bytes: int
    blocks_bytes: int = 0

    @property
    def arrays_bytes(self) -> int:
        """Bytes of the run's matrices: dense arrays, or element blocks and vectors."""
        return self.dense_bytes + self.blocks_bytes

    @property
    def needed(self) -> int:
        """Bytes the run adds to the process: matrices and records."""
        return self.arrays_bytes + self.records_bytes

    @property
    def total(self) -> int:
        """Estimated peak resident memory of a process doing only this run [bytes]."""
        return int(RUNTIME_BYTES) + self.needed


def dense_matrices(model: Model, scheme: AbstractScheme) -> int:
    """Dense n × n arrays a run of ``model`` by ``scheme`` holds at its peak, per member.

    Counted from the code of a step (static structure only, nothing evaluated):

    - kept for the whole run (:func:`~nsga_jax._integrators.operators.prepare_operators`):
      a constant M (1), a linear force's K and C (2), the inverse of each
      constant iteration matrix (1 each; a tridiagonal one keeps only blocks);
    - held factorisations (:class:`~nsga_jax._integrators.iteration_matrix.Held`,
      modified Newton in DS): one LU per sub-problem in the state, which a
      compiled chunk takes and returns (2 each);
    - where an iteration matrix is refactored (every non-constant kind):
      the assembled tangent K, the matrix A (eqs. 47-49) and its LU factors
      (3), with C for a velocity-dependent force (1), M(q) and its
      ``jacfwd`` K_M for a varying mass (2), the curvature K_g of
      non-affine constraints (1);
    - a model of constant iteration matrices only: A and LAPACK's copy of it
      while each inverse is formed (2).
    """
    from ._integrators.iteration_matrix import ConstantInverse

    kinds = [k for k, p in zip(scheme.matrix_kinds(model), present_subproblems(model, scheme)) if p]
    if assembles_nothing(kinds):
        return 0
    count = int(model.constant_mass) + 2 * int(model.linear_force)
    count += sum(1 for k in kinds if issubclass(k, ConstantInverse)) + 2 * sum(1 for k in kinds if k.is_held)
    if any(not k.is_constant for k in kinds):
        count += 3 + int(model.velocity_dependent_force) + 2 * int(not model.constant_mass)
        count += int(not model.linear_constraints and model.n_constraints > 0)
    elif kinds:
        count += 2
    return max(count, 1)


BLOCK_COPIES = 23
"""Element-block arrays (E × k × k numbers each) a run that assembles no
matrix holds at its peak, XLA's temporaries of the stiffness rebuild
included: fitted on the cube's measured peaks past :data:`RUNTIME_BYTES`
at 20, 25 and 30 divisions (26 times the element blocks' bytes at each,
with :data:`OVERHEAD`; docs/performance.md, "Large models")."""

VECTOR_COPIES = 60
"""Vectors of n numbers the same run holds: state, predictor, residuals and
conjugate-gradient work vectors of three sub-problems."""

FRICTION_ROW_COPIES = 8
"""With Coulomb friction, arrays of m × n numbers (m = nc + nf · d contact
rows) the matrix-free path holds: the rows spelled out, A⁻¹ Gᵀ and the
work vectors of its m conjugate-gradient solves, batched
(:func:`~nsga_jax._integrators.contact_rows.dense_rows`); and
:data:`FRICTION_SYSTEM_COPIES` arrays of (2m)² numbers, the contact law's
Newton system and its SVD. Both counted from the arrays a step forms, not
fitted on measured peaks as :data:`BLOCK_COPIES` is."""

FRICTION_SYSTEM_COPIES = 6


def assembles_nothing(kinds) -> bool:
    from ._integrators.krylov import KRYLOV_KINDS

    return bool(kinds) and all(issubclass(k, KRYLOV_KINDS) for k in kinds)


def matrix_free_numbers(model: Model, scheme: AbstractScheme) -> int:
    """Numbers a run that assembles no matrix (:mod:`~nsga_jax._integrators.krylov`)
    holds at its peak, per member: :data:`BLOCK_COPIES` arrays of element
    blocks (their size from ``jax.eval_shape``, nothing evaluated) and
    :data:`VECTOR_COPIES` vectors, and with friction the contact rows' arrays
    (:data:`FRICTION_ROW_COPIES`); 0 for a run with dense matrices."""
    kinds = [k for k, p in zip(scheme.matrix_kinds(model), present_subproblems(model, scheme)) if p]
    if not assembles_nothing(kinds):
        return 0
    import jax
    import jax.numpy as jnp

    blocks = jax.eval_shape(model.element_mass, jax.ShapeDtypeStruct((model.n_dof,), jnp.float32)).blocks
    numbers = BLOCK_COPIES * blocks.size + VECTOR_COPIES * model.n_dof
    if model.n_friction:
        m = model.n_constraints + model.n_friction * model.friction_dim
        numbers += FRICTION_ROW_COPIES * m * model.n_dof + FRICTION_SYSTEM_COPIES * (2 * m) ** 2
    return numbers


def present_subproblems(model: Model, scheme: AbstractScheme) -> tuple[bool, bool, bool]:
    """Which iteration matrices (smooth, position, velocity) a step of
    ``scheme`` solves with: Moreau–Jean's one velocity-level matrix; the
    generalized-α schemes' smooth one, and the other two with constraints."""
    if "moreau_jean" in scheme.subproblems:
        return False, False, True
    constrained = model.n_constraints > 0
    return True, constrained, constrained


def estimate_run_bytes(model: Model, scheme: AbstractScheme, itemsize: int = 8, *, members: int = 1,
                       records: int = 0, record_numbers: int = 0) -> Estimate:
    """The memory of a run, from sizes only.

    Args:
        model, scheme: what runs (only their static structure is read).
        itemsize: bytes per number of the run's precision (8: float64, 4: float32).
        members: runs held at once (a batch's members, each with its own matrices).
        records: recorded steps kept in memory per member (the initial state is added).
        record_numbers: numbers in one step's record.
    """
    n = model.n_dof
    dense = dense_matrices(model, scheme)
    dense_bytes = int(OVERHEAD * dense * n * n * itemsize * members)
    records_bytes = (records + 1) * record_numbers * itemsize * members if records else 0
    blocks_bytes = int(OVERHEAD * matrix_free_numbers(model, scheme) * itemsize * members)
    return Estimate(n, dense, itemsize, members, dense_bytes, records_bytes, blocks_bytes)


def available_memory() -> int | None:
    """Bytes a run can still allocate, or ``None`` where that is unknown.

    On an accelerator, its ``memory_stats()`` (``bytes_limit - bytes_in_use``);
    on the CPU, ``MemAvailable`` of ``/proc/meminfo`` (Linux), else the
    available physical pages (``os.sysconf``).
    """
    try:
        import jax

        device = jax.devices()[0]
        if device.platform != "cpu":
            stats = device.memory_stats()
            if stats and stats.get("bytes_limit"):
                return int(stats["bytes_limit"]) - int(stats.get("bytes_in_use", 0))
            return None  # an accelerator that does not say: do not guess from the host
    except Exception:  # no device statistics on this platform
        return None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def skipped() -> bool:
    """Whether :data:`SKIP_ENV` asks to skip the check."""
    return os.environ.get(SKIP_ENV, "").strip().lower() not in ("", "0", "false", "no")


def gigabytes(n_bytes: float) -> str:
    """``n_bytes`` in GB (10⁹ bytes): whole GB from 100 GB, one decimal from
    1 GB, three significant digits below."""
    gb = n_bytes / 1e9
    return f"{gb:,.0f} GB" if gb >= 100 else f"{gb:.1f} GB" if gb >= 1 else f"{gb:.3g} GB"


def kept_records(model: Model, scheme: AbstractScheme, n_steps: int, every: int = 1) -> tuple[int, int]:
    """The ``records`` and ``record_numbers`` of :func:`check_fits` for a run
    of ``n_steps`` steps keeping every ``every``-th (and the last): how many
    rows it keeps and the numbers in each."""
    import numpy as np

    from ._integrators.records import output_template, packed_sizes

    template = output_template(model, np.dtype("float64"), scheme.subproblems)
    return n_steps // every + (n_steps % every > 0), sum(packed_sizes(template))


def check_fits(model: Model, scheme: AbstractScheme, itemsize: int = 8, *, members: int = 1, records: int = 0,
               record_numbers: int = 0, what: str = "the model", enabled: bool = True) -> Estimate:
    """Refuse a run that cannot fit in :func:`available_memory`, before anything is compiled.

    Raises :class:`~nsga_jax.ConfigError` naming the size, the estimate, the
    available memory and what to do when the dense arrays, or the dense
    arrays and the kept records, exceed it. Nothing is refused where the
    available memory is unknown, with ``enabled=False`` or with
    :data:`SKIP_ENV` set. Returns the estimate.
    """
    est = estimate_run_bytes(model, scheme, itemsize, members=members, records=records,
                             record_numbers=record_numbers)
    if not enabled or skipped():
        return est
    limit = available_memory()
    if limit is None or est.needed <= limit:
        return est
    each = f" for each of {members} runs" if members > 1 else ""
    skip = f"; to run anyway, pass check_memory=False or set {SKIP_ENV}=1"
    if est.blocks_bytes > limit:
        raise ConfigError(
            f"{what}: {gigabytes(est.blocks_bytes)} estimated for {est.n_dof:,} coordinates (element blocks and "
            f"vectors, no matrix assembled, {itemsize} bytes a number{each}), {gigabytes(limit)} available; use a "
            f"smaller model{' or fewer runs at once' if members > 1 else ''}{skip}")
    if est.dense_bytes > limit:
        raise ConfigError(
            f"{what}: {gigabytes(est.dense_bytes)} estimated for {est.n_dof:,} coordinates (about {est.dense} dense "
            f"{est.n_dof:,} x {est.n_dof:,} iteration matrices, {itemsize} bytes a number{each}), "
            f"{gigabytes(limit)} available; use a smaller model (a coarser mesh, fewer divisions or elements)"
            f"{' or fewer runs at once' if members > 1 else ''}{skip}")
    raise ConfigError(
        f"{what}: keeping the records of {records:,} steps needs {gigabytes(est.records_bytes)} ({record_numbers} "
        f"numbers a step{each}) beside {gigabytes(est.arrays_bytes)} of matrices, {gigabytes(limit)} "
        f"available; keep every k-th step (SaveAt(every=k), record_every / --record-every) or shorten the run{skip}")


__all__ = ["OVERHEAD", "RUNTIME_BYTES", "SKIP_ENV", "Estimate", "available_memory", "check_fits", "dense_matrices",
           "assembles_nothing", "estimate_run_bytes", "matrix_free_numbers", "present_subproblems", "skipped"]
