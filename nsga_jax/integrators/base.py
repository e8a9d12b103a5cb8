"""What every time-stepping scheme shares: the carried state, the per-step
record and the scheme interface (the operators a scheme prepares are in
:mod:`~nsga_jax.integrators.operators`).

Records are physical: λ̃ [N], ν [N s²] and the impulse Λ [N s] (Λ/h is the
mean contact force over the step).
"""

from __future__ import annotations

import abc
import math
from typing import Any, cast

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Scalar, ScalarLike, Vector
from .._util import as_float
from ..models.base import Model
from ..results import Result
from .newton import NewtonResult
from .operators import MatrixKinds, Operators

# --------------------------------------------------------------------------- data


class StepState(eqx.Module):
    """What a scheme carries from step to step.

    t [s]; q, v (n,): coordinates and velocities; vd (n,): smooth acceleration
    v̇̃; a (n,): generalized-α pseudo-acceleration (both zero for Moreau–Jean);
    factorisations: the iteration-matrix factorisations a scheme keeps for its
    next step (one per sub-problem, ``None`` where it keeps none; see
    :attr:`~nsga_jax.integrators.ds.DS.reuse_min_dof`), or ``None``.
    """

    t: Scalar
    q: Vector
    v: Vector
    vd: Vector
    a: Vector
    factorisations: tuple | None = None


class StepOutput(eqx.Module):
    """Per-step record (stacked over steps by the time loop).

    Shapes: q, v (n,); lam (nb,): smooth bilateral multipliers [N];
    nu (nc,): position multipliers; impulse (nc,): Λ [N s] on the velocity
    active set; gap (nu,): g^U(q_{n+1}); bilateral (nb,): g^B(q_{n+1});
    bilateral_rate (nb,): g_q^B v_{n+1}; active_position, active_velocity (nc,);
    iterations (3,): linear solves of the smooth, position and velocity
    sub-problems (their sum is the step's number of linear solves);
    residual, tolerance (3,): final residual norms and their bounds;
    result: :class:`~nsga_jax.results.Result` code.
    """

    t: Scalar
    q: Vector
    v: Vector
    lam: jax.Array
    nu: jax.Array
    impulse: jax.Array
    gap: jax.Array
    bilateral: jax.Array
    bilateral_rate: jax.Array
    active_position: jax.Array
    active_velocity: jax.Array
    iterations: jax.Array
    residual: jax.Array
    tolerance: jax.Array
    result: jax.Array


# ------------------------------------------------------------------- results


def result_code(results: list[NewtonResult]) -> jax.Array:
    """Code of the first failing sub-problem (smooth, position, velocity order);
    a non-finite residual beats the iteration cap."""
    code = jnp.int8(Result.successful)
    for i in reversed(range(len(results))):
        r = results[i]
        this = jnp.where(~jnp.isfinite(r.residual_norm), jnp.int8(4 + i), jnp.int8(1 + i))
        code = jnp.where(~r.converged, this, code)
    return code


def make_output(model: Model, t, q, v, lam, iterations, residual, tolerance, result,
                nu=None, impulse=None, g=None, gdot=None, active_position=None, active_velocity=None) -> StepOutput:
    """Assemble a :class:`StepOutput`; constraint fields default to empty or zero."""
    nb, nc = model.n_bilateral, model.n_constraints
    zeros = jnp.zeros((nc,), q.dtype)
    no = jnp.zeros((nc,), bool)
    g = model.constraints(q) if g is None else g
    gdot = constraint_jacobian_or_empty(model, q) @ v if gdot is None else gdot
    return StepOutput(
        t=t, q=q, v=v, lam=lam,
        nu=zeros if nu is None else nu,
        impulse=zeros if impulse is None else impulse,
        gap=g[nb:], bilateral=g[:nb], bilateral_rate=gdot[:nb],
        active_position=no if active_position is None else active_position,
        active_velocity=no if active_velocity is None else active_velocity,
        iterations=jnp.stack(iterations).astype(jnp.int32),
        residual=jnp.stack(residual), tolerance=jnp.stack(tolerance), result=result,
    )


def output_template(model: Model, dtype) -> StepOutput:
    """Shapes and dtypes of one step's :class:`StepOutput` (what
    :func:`make_output` returns), from the model's sizes alone: the time loops
    size their record buffers with it instead of tracing the step once more."""
    n, nb, nc, nu = model.n_dof, model.n_bilateral, model.n_constraints, model.n_unilateral

    def f(*shape, dtype=dtype) -> Any:  # a ShapeDtypeStruct where StepOutput's fields are typed as arrays
        return jax.ShapeDtypeStruct(shape, dtype)

    flags = f(nc, dtype=jnp.bool_)
    return StepOutput(t=f(), q=f(n), v=f(n), lam=f(nb), nu=f(nc), impulse=f(nc), gap=f(nu), bilateral=f(nb),
                      bilateral_rate=f(nb), active_position=flags, active_velocity=flags,
                      iterations=f(3, dtype=jnp.int32), residual=f(3), tolerance=f(3),
                      result=f(dtype=jnp.int8))


def _is_float(spec) -> bool:
    return jnp.issubdtype(spec.dtype, jnp.floating)


def pack_output(out: StepOutput) -> tuple[jax.Array, jax.Array]:
    """One step's record as two flat vectors: its floating-point fields and
    its integer and boolean fields (as int32). Writing two vectors per step
    into a time loop's buffers costs less than writing fifteen small arrays
    (each write is a separate operation on the CPU)."""
    leaves = jax.tree_util.tree_leaves(out)
    floats = [jnp.ravel(x) for x in leaves if _is_float(x)]
    ints = [jnp.ravel(x).astype(jnp.int32) for x in leaves if not _is_float(x)]
    return jnp.concatenate(floats), jnp.concatenate(ints)


def packed_sizes(template: StepOutput) -> tuple[int, int]:
    """Lengths of the two vectors :func:`pack_output` makes."""
    leaves = jax.tree_util.tree_leaves(template)
    return (sum(math.prod(x.shape) for x in leaves if _is_float(x)),
            sum(math.prod(x.shape) for x in leaves if not _is_float(x)))


def unpack_outputs(floats, ints, template: StepOutput) -> StepOutput:
    """Records (..., fields) packed by :func:`pack_output` back into a
    :class:`StepOutput` with the leading axes of ``floats``, typed as ``template``.
    On NumPy arrays the floating-point fields are views (nothing is copied):
    the time loops return their packed buffers and unpack them on the host."""
    lead = floats.shape[:-1]
    offsets = {True: 0, False: 0}
    leaves = []
    for spec in jax.tree_util.tree_leaves(template):
        kind = _is_float(spec)
        size = math.prod(spec.shape)
        source = floats if kind else ints
        part = source[..., offsets[kind]:offsets[kind] + size]
        offsets[kind] += size
        part = part.reshape(*lead, *spec.shape)
        leaves.append(part if part.dtype == spec.dtype else part.astype(spec.dtype))
    return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(template), leaves)


def constraint_jacobian_or_empty(model: Model, q: Vector) -> jax.Array:
    if model.n_constraints == 0:
        return jnp.zeros((0, model.n_dof), q.dtype)
    return model.constraint_jacobian(q)


# ------------------------------------------------------------------- schemes


class AbstractScheme(eqx.Module):
    """A time-stepping scheme: public ``prepare``, ``init`` and ``step``.

    ``step(model, ops, state, h) -> (state, record)`` is a pure function; the
    time loop (:func:`~nsga_jax.simulate`) scans it.

    Attributes:
        tol_r, tol_f: relative and reference tolerances of eq. 51.
        max_iter: iteration cap of each Newton loop (static).
        differentiable: make each Newton solve differentiable by the implicit
            function theorem (:func:`~nsga_jax.integrators.newton.solve`); set by
            :func:`~nsga_jax.trajectory`. Static.
        fast_paths: use what the model's static structure makes constant
            (mass, tangents, constraint Jacobian, inverted iteration matrices),
            computed once per run; ``False`` is the generic path, for checks
            and benchmarks. Static.
    """

    tol_r: ScalarLike = eqx.field(default=1e-5, converter=as_float)
    tol_f: ScalarLike = eqx.field(default=1e-5, converter=as_float)
    max_iter: int = eqx.field(static=True, default=50)
    differentiable: bool = eqx.field(static=True, default=False, kw_only=True)
    fast_paths: bool = eqx.field(static=True, default=True, kw_only=True)

    name = "abstract"

    @property
    def tolerances(self) -> tuple[Scalar, Scalar, int]:
        # tol_r and tol_f are typed as what __init__ accepts; their converter (as_float) made them arrays
        return cast(jax.Array, self.tol_r), cast(jax.Array, self.tol_f), self.max_iter

    @abc.abstractmethod
    def matrix_kinds(self, model: Model) -> MatrixKinds:
        """The kinds of the smooth, position and velocity iteration matrices
        :meth:`prepare` builds for ``model`` (static: nothing is evaluated;
        :mod:`~nsga_jax.integrators.iteration_matrix`)."""

    @abc.abstractmethod
    def prepare(self, model: Model, h: Scalar, t0: Scalar) -> Operators:
        """The operators for this model and step size: the model's terms and
        the iteration matrices, what is constant computed here (run once,
        outside the loop; :mod:`~nsga_jax.integrators.operators`)."""

    @abc.abstractmethod
    def init(self, model: Model, t0: Scalar, q0: Vector, v0: Vector) -> StepState:
        """The state at t0."""

    @abc.abstractmethod
    def step(self, model: Model, ops: Operators, state: StepState, h: Scalar) -> tuple[StepState, StepOutput]:
        """Advance one step of size h [s]."""

    def bounds(self) -> dict[str, tuple[jax.Array, float, float]]:
        """Scheme-specific settings and their closed ranges ``{name: (value, lo, hi)}``,
        checked before anything is traced."""
        return {}
