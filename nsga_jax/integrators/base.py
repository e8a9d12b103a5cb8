"""What every time-stepping scheme shares: the carried state, the constant
operators of a model, and the model-facing helpers of the Newton
sub-problems (the per-step record is in :mod:`~nsga_jax.integrators.records`).

Multipliers inside the sub-problems are scaled as in the paper (ks λ̃, kp ν,
kv Λ are the physical values); records are physical: λ̃ [N], ν [N s²] and the
impulse Λ [N s] (Λ/h is the mean contact force over the step).
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable
from typing import ClassVar, NamedTuple, cast

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Matrix, Scalar, ScalarLike, Vector
from .._util import as_float
from ..models.base import Model
from .linalg import Tridiagonal, band_matrix, band_product, inverse_solve
from .newton import Residual, convergence_bound
from .records import StepOutput

ROUNDOFF_FACTOR = 64.0
"""The residual floor is ``ROUNDOFF_FACTOR * eps * (||K|| ||q|| + ||C|| ||v||)``
(scaled like the residual), see :mod:`nsga_jax.integrators.newton`."""

DIVERGENCE_FACTOR = 1e10
"""A coupled iteration whose residual grows this many times beyond its start has diverged."""


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


class Operators(eqx.Module):
    """Constant pieces of a model for one step size, computed once per run.

    Each field is ``None`` when the model's structure does not make it
    constant: M (constant mass), K and C (linear force), G (affine
    constraints), and the inverses of the iteration matrices of the smooth,
    position and velocity sub-problems with the products A^{-1} G^T they need
    (for a chain of half-bandwidth 1, a block elimination of the tridiagonal
    matrix instead of its dense inverse: :class:`~nsga_jax.integrators.linalg.Tridiagonal`).
    """

    M: Matrix | None
    M_norm: Scalar | None
    K: Matrix | None
    C: Matrix | None
    K_norm: Scalar | None
    C_norm: Scalar | None
    G: jax.Array | None
    smooth_inv: Matrix | Tridiagonal | None
    smooth_inv_Gt: jax.Array | None
    position_inv: Matrix | Tridiagonal | None
    position_inv_Gt: jax.Array | None
    velocity_inv: Matrix | Tridiagonal | None
    velocity_inv_Gt: jax.Array | None
    M_band: jax.Array | None = None
    K_band: jax.Array | None = None
    C_band: jax.Array | None = None


def banded(model: Model) -> bool:
    """Whether a model's constant M and K are worked with on their band: a
    linear model with constant mass that declares a half-bandwidth b with
    2b + 1 <= n / 8 (a 1D chain); wider bands gain nothing over the dense or
    element-by-element products."""
    b = model.bandwidth
    return (b is not None and model.constant_mass and model.linear_force
            and 8 * (2 * b + 1) <= model.n_dof)


TopLeft = Callable[[Matrix, Matrix, Matrix], Matrix]
"""``(M, K, C) -> A``: the constraint-free block of an iteration matrix."""


def constant_operators(
    model: Model,
    t0: Scalar,
    smooth: TopLeft | None,
    position: TopLeft | None,
    velocity: TopLeft | None,
    smooth_needs_constant_G: bool,
    position_needs_constant_G: bool,
    velocity_needs_constant_G: bool = False,
    enabled: bool = True,
) -> Operators:
    """Evaluate what the model's structure makes constant and invert the given
    iteration matrices when they are constant.

    The smooth block couples only to the bilateral rows of g_q, the others to
    all rows. ``*_needs_constant_G``: the matrix holds the constraint
    curvature unless the constraints are affine, so it is constant only then.
    ``enabled=False`` keeps nothing (every field ``None``): the generic path,
    which evaluates and factors everything at every iteration.
    """
    if not enabled:
        return Operators(*([None] * len(dataclasses.fields(Operators))))
    n, nb, nc = model.n_dof, model.n_bilateral, model.n_constraints
    zeros = jnp.zeros((n,))
    M = model.mass(zeros) if model.constant_mass else None
    K = C = K_norm = C_norm = None
    if model.linear_force:
        K, C = model.tangents(zeros, zeros, t0)
        if not model.velocity_dependent_force:
            C = jnp.zeros_like(K)
        K_norm, C_norm = jnp.linalg.norm(K), jnp.linalg.norm(C)
    G = model.constraint_jacobian(zeros) if (model.linear_constraints and nc > 0) else None

    tridiagonal = banded(model) and model.bandwidth == 1

    def invert(top_left, needs_G, rows):
        if top_left is None or M is None or K is None or (needs_G and G is None):
            return None, None
        A = top_left(M, K, C)
        inv = Tridiagonal.of(band_matrix(A, 1)) if tridiagonal else jnp.linalg.inv(A)
        inv_Gt = inverse_solve(inv)(G[rows].T) if (G is not None and len(range(*rows.indices(nc)))) else None
        return inv, inv_Gt

    s_inv, s_Gt = invert(smooth, smooth_needs_constant_G and nb > 0, slice(0, nb))
    p_inv, p_Gt = invert(position if nc else None, position_needs_constant_G, slice(0, nc))
    v_inv, v_Gt = invert(velocity if nc else None, velocity_needs_constant_G, slice(0, nc))
    M_norm = None if M is None else jnp.linalg.norm(M)
    bands: dict[str, jax.Array | None] = {}
    if banded(model):
        b = model.bandwidth
        assert b is not None and M is not None and K is not None and C is not None  # banded: linear, constant mass
        bands = {"M_band": band_matrix(M, b), "K_band": band_matrix(K, b),
                 "C_band": band_matrix(C, b) if model.velocity_dependent_force else None}
    return Operators(M=M, M_norm=M_norm, K=K, C=C, K_norm=K_norm, C_norm=C_norm, G=G,
                     smooth_inv=s_inv, smooth_inv_Gt=s_Gt, position_inv=p_inv, position_inv_Gt=p_Gt,
                     velocity_inv=v_inv, velocity_inv_Gt=v_Gt, **bands)


class Scaling(eqx.Module):
    """Multiplier scalings and penalties (after eq. 50): ks = ps = m̄/h, kp = pp = kv = pv = m̄."""

    ks: Scalar
    kp: Scalar
    kv: Scalar

    @classmethod
    def of(cls, model: Model, h: Scalar) -> "Scaling":
        mbar = jnp.asarray(model.mbar, dtype=float)
        return cls(ks=mbar / h, kp=mbar, kv=mbar)


# ----------------------------------------------------------------- model helpers


def mass_matrix(model: Model, ops: Operators, q: Vector) -> Matrix:
    return ops.M if ops.M is not None else model.mass(q)


def tangents(model: Model, ops: Operators, q: Vector, v: Vector, t: Scalar):
    """K, C and their Frobenius norms (for the round-off floor)."""
    if ops.K is not None:
        return ops.K, ops.C, ops.K_norm, ops.C_norm
    K, C = model.tangents(q, v, t)
    if not model.velocity_dependent_force:
        C = jnp.zeros_like(K)
    return K, C, jnp.linalg.norm(K), jnp.linalg.norm(C)


class ForceAt(NamedTuple):
    """The force f = f(q, v, t) evaluated at one point (q, v) at the step's time t."""

    q: Vector
    v: Vector
    f: Vector


def force_at(model: Model, q: Vector, v: Vector, t: Scalar) -> ForceAt:
    return ForceAt(q, v, model.force(q, v, t))


def force_change(model: Model, ops: Operators, ref: ForceAt, q: Vector, v: Vector, t: Scalar) -> Vector:
    """f(q, v, t) - ref.f at the same time t. Evaluating f (element assembly, O(n))
    is cheaper than a dense tangent product; the round-off it leaves is what the
    Newton floor covers. A banded linear model (ops.K_band) uses its exact
    difference -K (q - ref.q) - C (v - ref.v) on the band instead."""
    if ops.K_band is None:
        return model.force(q, v, t) - ref.f
    df = -band_product(ops.K_band, q - ref.q)
    if ops.C_band is not None:
        df = df - band_product(ops.C_band, v - ref.v)
    return df


def force_near(model: Model, ops: Operators, ref: ForceAt, q: Vector, v: Vector, t: Scalar) -> Vector:
    """f(q, v, t), from ``ref`` and :func:`force_change` for a banded linear model."""
    return model.force(q, v, t) if ops.K_band is None else ref.f + force_change(model, ops, ref, q, v, t)


def mass_product(model: Model, ops: Operators, q: Vector, x: Vector) -> Vector:
    """M(q) @ x, on the band for a banded linear model."""
    return model.mass_product(q, x) if ops.M_band is None else band_product(ops.M_band, x)


def constraint_jacobian(model: Model, ops: Operators, q: Vector) -> jax.Array:
    """g_q(q) for all constraints, shape (nc, n)."""
    return ops.G if ops.G is not None else model.constraint_jacobian(q)


def bilateral_jacobian(model: Model, ops: Operators, q: Vector) -> jax.Array:
    """g_q^B(q), shape (nb, n)."""
    return ops.G[: model.n_bilateral] if ops.G is not None else jax.jacfwd(model.bilateral)(q)


def curvature(model: Model, q: Vector, mu: jax.Array) -> Matrix:
    """d(g_q(q)^T mu)/dq at fixed mu (mu over all nc constraints); zero if affine."""
    if model.linear_constraints or model.n_constraints == 0:
        return jnp.zeros((model.n_dof, model.n_dof), q.dtype)
    return jax.jacfwd(lambda x: model.constraint_jacobian(x).T @ mu)(q)


def convective(model: Model, q: Vector, v: Vector, bilateral_only: bool = False) -> jax.Array:
    """G^s = d(g_q(q) v)/dq at fixed v, shape (nb or nc, n); zero if affine."""
    rows = model.n_bilateral if bilateral_only else model.n_constraints
    if model.linear_constraints:
        return jnp.zeros((rows, model.n_dof), q.dtype)
    fn = model.bilateral if bilateral_only else model.constraints
    return jax.jacfwd(lambda x: jax.jacfwd(fn)(x) @ v)(q)


def mass_norm(model: Model, ops: Operators, q: Vector) -> Scalar:
    """Frobenius norm of M(q) (precomputed for a constant mass)."""
    return ops.M_norm if ops.M_norm is not None else jnp.linalg.norm(model.mass(q))


def roundoff_floor(scale: Scalar, K_norm, C_norm, q, v, inertia: ScalarLike = 0.0) -> Scalar:
    """``ROUNDOFF_FACTOR * eps * scale * (||K|| ||q|| + ||C|| ||v|| + inertia)``: the
    round-off of a residual whose terms cancel; ``inertia`` adds the round-off of
    an inertia term formed from a difference of velocities (step 1's v̇̃)."""
    eps = jnp.finfo(q.dtype).eps
    return ROUNDOFF_FACTOR * eps * scale * (K_norm * jnp.linalg.norm(q) + C_norm * jnp.linalg.norm(v) + inertia)


def constraint_floor(k: Scalar, G: jax.Array, x: Vector) -> Scalar:
    """``ROUNDOFF_FACTOR * eps * k * || |G| |x| ||``: the round-off of the scaled
    constraint rows ``k g_q v`` (x = v) or ``k g(q)`` (x = q, for gaps about as
    large as ``|g_q| |q|``) at their solution, where the rows' exact values are
    zero; row by row, so that one contact's round-off never excuses another's
    violation. Negligible in float64 against eq. 51's bound; in float32 it is
    what lets a converged projection pass the test."""
    eps = jnp.finfo(x.dtype).eps
    return ROUNDOFF_FACTOR * eps * k * jnp.linalg.norm(jnp.abs(G) @ jnp.abs(x))


def pad_bilateral(model: Model, lam: jax.Array) -> jax.Array:
    """Embed a bilateral multiplier (nb,) in the full constraint space (nc,)."""
    return jnp.concatenate([lam, jnp.zeros((model.n_unilateral,), lam.dtype)])


def is_unilateral(model: Model) -> jax.Array:
    return jnp.arange(model.n_constraints) >= model.n_bilateral


def restitution(model: Model, dtype) -> jax.Array:
    """Restitution over all constraints (nc,), zero on the bilaterals."""
    return jnp.concatenate([jnp.zeros((model.n_bilateral,), dtype), jnp.asarray(model.restitution, dtype)])


def augmented_residual(inertia, force, G, c, mu, k, p, candidates, unilateral, tol_r, tol_f) -> Residual:
    """Residual of a projection sub-problem (eqs. 37 and 42).

    With the augmented multiplier ``aug = k mu - p c`` and the active set
    ``candidates ∩ (bilateral ∪ {aug >= 0})``:
    ``[inertia - force - G^T aug_active;  -k c (active);  -(k²/p) mu (inactive)]``.
    Returns the :class:`Residual` with ``aux = (active, aug)``.
    """
    aug = k * mu - p * c
    active = candidates & (~unilateral | (aug >= 0))
    reaction = G.T @ jnp.where(active, aug, 0.0)
    r2 = jnp.where(active, -k * c, -(k**2 / p) * mu)
    r = jnp.concatenate([inertia - force - reaction, r2])
    return Residual(r, convergence_bound([inertia, force, reaction, r2], tol_r, tol_f), (active, aug))


def consistent_acceleration(model: Model, t0: Scalar, q0: Vector, v0: Vector) -> Vector:
    """v̇̃_0 from the equations of motion with the bilateral constraints at
    acceleration level, unilateral constraints ignored (Algorithm 1, line 2)."""
    M = model.mass(q0)
    f = model.force(q0, v0, t0)
    nb = model.n_bilateral
    if nb == 0:
        return jnp.linalg.solve(M, f)
    GB = jax.jacfwd(model.bilateral)(q0)
    conv = jax.jvp(lambda x: jax.jacfwd(model.bilateral)(x) @ v0, (q0,), (v0,))[1]
    S = jnp.block([[M, -GB.T], [GB, jnp.zeros((nb, nb))]])
    return jnp.linalg.solve(S, jnp.concatenate([f, -conv]))[: model.n_dof]


# ------------------------------------------------------------------- schemes


class AbstractScheme(eqx.Module):
    """A time-stepping scheme: public ``prepare``, ``init`` and ``step``.

    ``step(model, ops, state, h) -> (state, record)`` is a pure function; the
    time loop (:func:`~nsga_jax.simulate`) scans it.

    Attributes:
        tol_r, tol_f: relative and reference tolerances of eq. 51.
        max_iter: iteration cap of each Newton loop (static).
        fast_paths: use what the model's static structure makes constant
            (mass, tangents, constraint Jacobian, inverted iteration matrices),
            computed once per run; ``False`` is the generic path, for checks
            and benchmarks. Static.
    """

    tol_r: ScalarLike = eqx.field(default=1e-5, converter=as_float)
    tol_f: ScalarLike = eqx.field(default=1e-5, converter=as_float)
    max_iter: int = eqx.field(static=True, default=50)
    fast_paths: bool = eqx.field(static=True, default=True, kw_only=True)

    name = "abstract"
    subproblems: ClassVar[tuple[str, ...]] = ()
    """The names of the scheme's sub-problems, in the order its records keep them
    (:class:`~nsga_jax.integrators.records.NewtonRecord`)."""

    @property
    def tolerances(self) -> tuple[Scalar, Scalar, int]:
        # tol_r and tol_f are typed as what __init__ accepts; their converter (as_float) made them arrays
        return cast(jax.Array, self.tol_r), cast(jax.Array, self.tol_f), self.max_iter

    @abc.abstractmethod
    def prepare(self, model: Model, h: Scalar, t0: Scalar) -> Operators:
        """Constant operators for this model and step size (run once, outside the loop)."""

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
