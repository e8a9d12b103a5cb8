"""What a step reports: its record, its sub-problems' Newton statistics and
result, and the named outputs the sub-problems hand to the step.

Each scheme declares statically the names of its sub-problems
(``scheme.subproblems``: DS and DSn ``("smooth", "position", "velocity")``,
CS ``("coupled",)``, MJ ``("moreau_jean",)``); a step's
:class:`NewtonRecord` holds their iterations, residuals and bounds in that
order, read by name with ``record["position"]``. A step's result is a
:data:`~nsga_jax._results.RESULTS` member, combined with ``RESULTS.where``
(:func:`first_failure`); the record stores its code.

The time loops write each step's record as two flat vectors
(:func:`pack_output`) and unpack them on the host (:func:`unpack_outputs`).
Records are physical: λ̃ [N], ν [N s²] and the impulse Λ [N s] (Λ/h is the
mean contact force over the step).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .._custom_types import ActiveSet, ConstraintMatrix, ConstraintVector, Scalar, Vector
from .._models.base import Model
from .._results import RESULTS, code_of
from .newton import NewtonResult

PerStep = Int[Array, "..."]
"""An integer per step (a scalar in one step; leading axes: steps, members)."""
PerStepReal = Float[Array, "..."]
PerSubproblem = Int[Array, "... k"]
"""An integer per sub-problem (k of them) and step."""
PerSubproblemReal = Float[Array, "... k"]
PerConstraintFlag = Bool[Array, "... nc"]

# ------------------------------------------------------------- sub-problem outputs


class PositionAux(NamedTuple):
    """What the position correction's residual (eq. 37) hands on, at its iterate.

    active (nc,): the active set A; multiplier (nc,): the augmented multiplier
    ξ = kp ν - pp g [N s²]; gap (nc,): g(q) [m] at q = q̃ + U; jacobian (nc, n): g_q(q).
    """

    active: ActiveSet
    multiplier: ConstraintVector
    gap: ConstraintVector
    jacobian: ConstraintMatrix


class VelocityAux(NamedTuple):
    """What a velocity-level residual (the velocity jump, eq. 42, or the
    Moreau–Jean step) hands on, at its iterate.

    active (nc,): the active set; multiplier (nc,): the augmented multiplier
    σ = kv Λ - pv ġ [N s]; rate (nc,): ġ = g_q v + e g_q v_n [m/s] (the
    restitution term on the unilaterals).
    """

    active: ActiveSet
    multiplier: ConstraintVector
    rate: ConstraintVector
    friction: jax.Array | None = None
    """The tangential impulses P_T (nf · d,) [N s] of the frictional contacts
    (``None`` without friction)."""


# ------------------------------------------------------------ Newton statistics


class SubproblemRecord(NamedTuple):
    """One sub-problem's Newton statistics: iterations (linear solves), final
    residual norm and its bound (eq. 51). Scalars in one step, (N,) over N steps."""

    iterations: PerStep
    residual: PerStepReal
    tolerance: PerStepReal

    @classmethod
    def of(cls, sol: NewtonResult) -> SubproblemRecord:
        return cls(sol.iterations, sol.residual_norm, sol.tolerance)


class NewtonRecord(eqx.Module):
    """The Newton statistics of a scheme's sub-problems, named.

    ``names`` (static): the scheme's sub-problems; ``iterations`` (..., k):
    linear solves of each (their sum is the step's number of linear solves;
    CS: its coupled iteration's, three per global iteration); ``residual``,
    ``tolerance`` (..., k): final residual norms and their bounds. Leading
    axes: steps (and members), once the loop stacks them.
    """

    names: tuple[str, ...] = eqx.field(static=True)
    iterations: PerSubproblem
    residual: PerSubproblemReal
    tolerance: PerSubproblemReal

    @classmethod
    def of(cls, names: Sequence[str], records: dict[str, SubproblemRecord], dtype) -> NewtonRecord:
        """One step's record, in the order of ``names``; a sub-problem not in
        ``records`` (not solved in this model: DS without constraints) has
        zero iterations and residual."""
        zero = SubproblemRecord(jnp.zeros((), jnp.int32), jnp.zeros((), dtype), jnp.zeros((), dtype))
        rows = [records.get(name, zero) for name in names]
        return cls(names=tuple(names),
                   iterations=jnp.stack([jnp.asarray(r.iterations, jnp.int32) for r in rows]),
                   residual=jnp.stack([jnp.asarray(r.residual, dtype) for r in rows]),
                   tolerance=jnp.stack([jnp.asarray(r.tolerance, dtype) for r in rows]))

    def __getitem__(self, name: str) -> SubproblemRecord:
        """The statistics of the sub-problem ``name`` (over every leading axis)."""
        if name not in self.names:
            raise KeyError(f"no sub-problem {name!r}; this scheme has {', '.join(self.names)}")
        i = self.names.index(name)
        return SubproblemRecord(self.iterations[..., i], self.residual[..., i], self.tolerance[..., i])


def subproblem_result(name: str, sol: NewtonResult) -> Any:
    """The :data:`~nsga_jax._results.RESULTS` member of one Newton sub-problem:
    ``successful``, or its non-finite member if the residual is not finite,
    else its iteration-cap member (``{name}_max_iter``)."""
    failed = RESULTS.where(jnp.isfinite(sol.residual_norm), getattr(RESULTS, f"{name}_max_iter"),
                           getattr(RESULTS, f"{name}_nonfinite"))
    return RESULTS.where(sol.converged, RESULTS.successful, failed)


def first_failure(results: Sequence[Any]) -> Any:
    """The first of ``results`` (in the sub-problems' order) that is not
    successful, or ``RESULTS.successful``."""
    out = RESULTS.successful
    for r in reversed(results):
        out = RESULTS.where(r == RESULTS.successful, out, r)
    return out


# ------------------------------------------------------------------ the record


class StepOutput(eqx.Module):
    """Per-step record (stacked over steps by the time loop).

    Shapes: q, v (n,); lam (nb,): smooth bilateral multipliers [N];
    nu (nc,): position multipliers; impulse (nc,): Λ [N s] on the velocity
    active set; gap (nu,): g^U(q_{n+1}); bilateral (nb,): g^B(q_{n+1});
    bilateral_rate (nb,): g_q^B v_{n+1}; active_position, active_velocity (nc,);
    friction (nf · d,): the tangential impulses P_T [N s] of the frictional
    contacts, contact by contact (empty without friction);
    newton: the :class:`NewtonRecord` of the scheme's sub-problems;
    instants: impacts resolved at their instants in the step (int32; 0 but
    with ``DS(impact_instants=True)``, :mod:`~nsga_jax._integrators.impact_instants`);
    fallback: the step reached its cap of instants and took what was left
    as one paper step (bool);
    result: the code of the step's :data:`~nsga_jax._results.RESULTS` member
    (int32; ``Result(code)`` on the host, :func:`~nsga_jax._results.from_code` in JAX).
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
    active_position: PerConstraintFlag
    active_velocity: PerConstraintFlag
    friction: jax.Array
    newton: NewtonRecord
    instants: PerStep
    fallback: Bool[Array, "..."]
    result: PerStep


def make_output(model: Model, t, q, v, lam, newton: NewtonRecord, result, nu=None, impulse=None, g=None, gdot=None,
                active_position=None, active_velocity=None, friction=None) -> StepOutput:
    """Assemble a :class:`StepOutput` (``result``: a :data:`~nsga_jax._results.RESULTS`
    member); constraint fields default to empty or zero."""
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
        friction=jnp.zeros((model.n_friction * model.friction_dim,), q.dtype) if friction is None else friction,
        newton=newton, instants=jnp.zeros((), jnp.int32), fallback=jnp.zeros((), bool), result=code_of(result),
    )


def constraint_jacobian_or_empty(model: Model, q: Vector) -> jax.Array:
    if model.n_constraints == 0:
        return jnp.zeros((0, model.n_dof), q.dtype)
    return model.constraint_jacobian(q)


def output_template(model: Model, dtype, subproblems: Sequence[str]) -> StepOutput:
    """Shapes and dtypes of one step's :class:`StepOutput` (what
    :func:`make_output` returns) for a scheme with these ``subproblems``, from
    the model's sizes alone: the time loops size their record buffers with it
    instead of tracing the step once more."""
    n, nb, nc, nu = model.n_dof, model.n_bilateral, model.n_constraints, model.n_unilateral
    k = len(subproblems)

    def f(*shape, dtype=dtype) -> Any:  # a ShapeDtypeStruct where StepOutput's fields are typed as arrays
        return jax.ShapeDtypeStruct(shape, dtype)

    flags = f(nc, dtype=jnp.bool_)
    newton = NewtonRecord(names=tuple(subproblems), iterations=f(k, dtype=jnp.int32), residual=f(k), tolerance=f(k))
    return StepOutput(t=f(), q=f(n), v=f(n), lam=f(nb), nu=f(nc), impulse=f(nc), gap=f(nu), bilateral=f(nb),
                      bilateral_rate=f(nb), active_position=flags, active_velocity=flags,
                      friction=f(model.n_friction * model.friction_dim), newton=newton,
                      instants=f(dtype=jnp.int32), fallback=f(dtype=jnp.bool_), result=f(dtype=jnp.int32))


# ------------------------------------------------------------ packing


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


__all__ = ["NewtonRecord", "PositionAux", "StepOutput", "SubproblemRecord", "VelocityAux", "first_failure",
           "make_output", "output_template", "pack_output", "packed_sizes", "subproblem_result", "unpack_outputs"]
