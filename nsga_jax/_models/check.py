"""``check_model``: a model's declared structure against its own functions.

A model declares its sizes and structure by hand (``n_dof``, ``constant_mass``,
``linear_force``, ``velocity_dependent_force``, ``linear_constraints``,
``bandwidth``) and the integrator trusts them: a constant mass is evaluated
once, a linear force's tangents are formed once, affine constraints keep one
Jacobian, a band is used for products. A flag the functions do not obey is
silently wrong physics. :func:`check_model` evaluates the functions at random
states around ``q`` and ``v`` (with ``jax.jacfwd`` for the derivatives) and
names every declaration they contradict.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._precision import require_x64
from .._results import ConfigError
from .base import Model

RELATIVE = 1e-8
"""Two evaluations differ when they differ by more than this, relative to their size."""


def _differ(a, b) -> float:
    """The largest difference of two arrays relative to their size (0 when equal)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    scale = max(float(np.abs(a).max(initial=0.0)), float(np.abs(b).max(initial=0.0)), 1e-300)
    return float(np.abs(a - b).max(initial=0.0)) / scale


def check_model(model: Model, q=None, v=None, t: float = 0.0, *, samples: int = 3, seed: int = 0,
                spread: float = 0.1) -> list[str]:
    """Compare every declared size and structure flag of ``model`` with its
    functions at ``samples`` random states near ``(q, v)`` (default: zeros)
    and return what was checked; raise :class:`~nsga_jax.ConfigError` naming
    the first flag or size the functions contradict (or, before anything,
    saying that JAX's 64-bit mode is off: the comparisons are made in float64).

    Checked: the shapes of ``mass`` (n, n), ``force`` (n,), ``bilateral``
    (nb,), ``unilateral`` (nu,) and ``restitution`` (nu,); ``mass_product``
    and ``tangents`` against ``mass`` and ``jax.jacfwd(force)``;
    ``constant_mass``, ``linear_force`` (K and C the same at every state),
    ``velocity_dependent_force=False`` (no ∂f/∂v), ``linear_constraints``
    (the same g_q at every state), a declared ``bandwidth`` (M and K zero
    outside the band) and ``body_coupling`` (M, K, C and g_q zero between
    what it does not couple), with friction its structure (normal rows,
    coefficients, the tangent Jacobian's shape), for a ``matrix_free``
    model its element blocks and node rows against M, K and g_q, and with an
    energy its kinetic part (∂E/∂v = M v) and, where the force is
    conservative, its potential (∂E/∂q = -f). What every model gives is
    checked first; then each capability the model declares
    (:data:`CAPABILITIES`, :mod:`nsga_jax._models.capabilities`).

    Args:
        q, v: the state to sample around, shape (n,) (default zeros).
        t: the time at which the force is evaluated [s].
        samples: random states compared, each ``q + spread N(0, 1)``.
    """
    require_x64("check_model")  # its comparisons are relative to 1e-8
    n, nb, nu = model.n_dof, model.n_bilateral, model.n_unilateral
    cls = type(model).__name__
    q0 = jnp.zeros(n) if q is None else jnp.asarray(q, float)
    v0 = jnp.zeros(n) if v is None else jnp.asarray(v, float)
    time = jnp.asarray(t, float)
    rng = np.random.default_rng(seed)
    states = [(q0 + spread * jnp.asarray(rng.standard_normal(n)), v0 + spread * jnp.asarray(rng.standard_normal(n)))
              for _ in range(max(2, samples))]

    def fail(flag: str, what: str) -> None:
        raise ConfigError(f"{cls}.{flag}: {what}")

    expected = {"mass": (n, n), "force": (n,), "bilateral": (nb,), "unilateral": (nu,)}
    qs, vs = states[0]
    got = {"mass": model.mass(qs).shape, "force": model.force(qs, vs, time).shape,
           "bilateral": model.bilateral(qs).shape, "unilateral": model.unilateral(qs).shape}
    for name, shape in expected.items():
        if tuple(got[name]) != shape:
            size = {"mass": "n_dof", "force": "n_dof", "bilateral": "n_bilateral", "unilateral": "n_unilateral"}[name]
            fail(size, f"{name}() has shape {tuple(got[name])}, where the declared sizes say {shape}")
    if tuple(jnp.shape(model.restitution)) != (nu,):
        fail("n_unilateral", f"restitution has shape {tuple(jnp.shape(model.restitution))}, expected ({nu},)")
    checked = ["sizes"]

    sampled = _Samples(time, tuple(states), *_evaluate(model, states, time, fail))
    checked += ["mass_product", "tangents"]
    for capability in CAPABILITIES:
        if capability.declared(model):
            capability.check(model, sampled, fail)
            checked.append(capability.name)
    return checked


class _Samples(NamedTuple):
    """The model's matrices at the sampled states, each a list over states."""

    time: jax.Array
    states: tuple[tuple[jax.Array, jax.Array], ...]
    masses: list
    stiffness: list
    damping: list
    jacobians: list


Fail = Callable[[str, str], None]


def _evaluate(model: Model, states, time, fail: Fail) -> tuple[list, list, list, list]:
    """What every model gives, at each state: M, K and C (from ``jax.jacfwd``
    of the force) and g_q; ``mass_product`` and ``tangents`` checked against
    them."""

    @jax.jit
    def evaluate(qs, vs):  # one compiled program for every sample: op by op, a system's jacfwd takes seconds
        return (model.mass(qs), model.mass_product(qs, vs), -jax.jacfwd(model.force, argnums=0)(qs, vs, time),
                -jax.jacfwd(model.force, argnums=1)(qs, vs, time), model.tangents(qs, vs, time),
                model.constraint_jacobian(qs) if model.n_constraints else None)

    masses, stiffness, damping, jacobians = [], [], [], []
    for qs, vs in states:
        M, product, K, C, (K_model, C_model), G = evaluate(qs, vs)
        if _differ(product, M @ vs) > RELATIVE:
            fail("mass_product", f"M(q) x differs from mass(q) @ x by {_differ(product, M @ vs):.2e} (relative)")
        if _differ(K_model, K) > 1e-6:
            fail("tangents", f"K differs from -d(force)/dq (jax.jacfwd) by {_differ(K_model, K):.2e} (relative)")
        if model.velocity_dependent_force and _differ(C_model, C) > 1e-6:
            fail("tangents", f"C differs from -d(force)/dv (jax.jacfwd) by {_differ(C_model, C):.2e} (relative)")
        masses.append(M)
        stiffness.append(K)
        damping.append(C)
        if G is not None:
            jacobians.append(G)
    return masses, stiffness, damping, jacobians


def _force_without_v(model: Model, s: _Samples, fail: Fail) -> None:
    worst = max(float(jnp.abs(C).max(initial=0.0)) for C in s.damping)
    if worst > 0.0:
        fail("velocity_dependent_force", f"declared False, but the force depends on v (|df/dv| up to {worst:.3g})")


def _constant_mass(model: Model, s: _Samples, fail: Fail) -> None:
    change = max(_differ(M, s.masses[0]) for M in s.masses[1:])
    if change > RELATIVE:
        fail("constant_mass", f"declared True, but M(q) changes with q (by {change:.2e}, relative)")


def _linear_force(model: Model, s: _Samples, fail: Fail) -> None:
    change = max(max(_differ(K, s.stiffness[0]), _differ(C, s.damping[0]))
                 for K, C in zip(s.stiffness[1:], s.damping[1:]))
    if change > RELATIVE:
        fail("linear_force", f"declared True, but the tangents K, C change with (q, v) (by {change:.2e}, relative)")


def _linear_constraints(model: Model, s: _Samples, fail: Fail) -> None:
    change = max(_differ(G, s.jacobians[0]) for G in s.jacobians[1:])
    if change > RELATIVE:
        fail("linear_constraints", f"declared True, but the constraint Jacobian g_q changes with q (by "
                                   f"{change:.2e}, relative)")


def _bandwidth(model: Model, s: _Samples, fail: Fail) -> None:
    b = model.bandwidth
    n = model.n_dof
    outside = np.abs(np.subtract.outer(np.arange(n), np.arange(n))) > b
    for name, A in (("M", s.masses[0]), ("K", s.stiffness[0]), ("C", s.damping[0])):
        worst = float(np.abs(np.asarray(A))[outside].max(initial=0.0))
        if worst > 0.0:
            fail("bandwidth", f"declared {b}, but {name} has entries up to {worst:.3g} outside that band")


def _body_coupling(model: Model, s: _Samples, fail: Fail) -> None:
    """M, K and C zero between bodies that no force couples; each row of g_q
    zero outside its bodies' coordinates (the constraints' curvature then
    stays within them too)."""
    coupling = model.body_coupling
    assert coupling is not None
    n, m = model.n_dof, model.n_constraints
    if coupling.dofs and (coupling.dofs[0][0] != 0 or coupling.dofs[-1][1] != n or len(coupling.rows) != m):
        fail("body_coupling", f"declares coordinates 0..{coupling.dofs[-1][1]} and {len(coupling.rows)} rows, "
                              f"the model has {n} coordinates and {m} rows")
        return
    outside = ~coupling.allowed_matrix()
    for name, matrices in (("M", s.masses), ("K", s.stiffness), ("C", s.damping)):
        worst = max(float(np.abs(np.asarray(A))[outside].max(initial=0.0)) for A in matrices)
        if worst > 0.0:
            fail("body_coupling", f"declared, but {name} couples bodies it does not name (entries up to {worst:.3g})")
    if m:
        outside = ~coupling.allowed_rows()
        worst = max(float(np.abs(np.asarray(G))[outside].max(initial=0.0)) for G in s.jacobians)
        if worst > 0.0:
            fail("body_coupling", f"declared, but g_q has entries up to {worst:.3g} outside its rows' bodies")


def _energy(model: Model, s: _Samples, fail: Fail) -> None:
    """The energy's kinetic part is ½ vᵀ M(q) v: ∂E/∂v = M(q) v at every
    state. Where the force is conservative (a constant mass, no dependence on
    v or t), its potential is the rest: ∂E/∂q = -f(q)."""
    grad = jax.jit(jax.grad(model.energy, argnums=(0, 1)))
    conservative = model.constant_mass and not model.velocity_dependent_force
    for (q, v), M in zip(s.states, s.masses):
        dE_dq, dE_dv = grad(q, v)
        if _differ(dE_dv, M @ v) > 1e-6:
            fail("energy", f"dE/dv differs from M(q) v by {_differ(dE_dv, M @ v):.2e} (relative): the kinetic "
                           "energy is not 1/2 v^T M v")
        f = model.force(q, v, s.time)
        if conservative and _differ(model.force(q, v, s.time + 1.0), f) <= RELATIVE and _differ(dE_dq, -f) > 1e-6:
            fail("energy", f"dE/dq differs from -f(q) by {_differ(dE_dq, -f):.2e} (relative), where the force "
                           "depends on q alone: the potential energy is not the force's")


class Capability(NamedTuple):
    """A capability a model may declare, and its check against the model's functions."""

    name: str
    declared: Callable[[Model], bool]
    check: Callable[[Model, _Samples, Fail], None]


def _check_matrix_free(model: Model, states, masses, stiffness, jacobians, fail) -> None:
    """A matrix-free model's element blocks and node rows against its dense
    M, K and g_q, and the structure the iterative path relies on: a constant
    mass, no damping, affine constraints, orthonormal rows."""
    for flag, ok in (("constant_mass", model.constant_mass),
                     ("velocity_dependent_force", not model.velocity_dependent_force),
                     ("linear_constraints", model.linear_constraints or model.n_constraints == 0)):
        if not ok:
            fail("matrix_free", f"declared True, but {flag} rules it out")
    for (qs, _), M, K in zip(states, masses, stiffness):
        for name, blocks, dense in (("element_mass", model.element_mass(qs), M),
                                    ("element_stiffness", model.element_stiffness(qs), K)):
            for form in (blocks, blocks.node_blocks()):
                if _differ(form.dense(), dense) > 1e-6:
                    fail(name, f"its blocks differ from the assembled matrix by {_differ(form.dense(), dense):.2e} "
                               "(relative)")
    kronecker = model.kronecker_mass()
    if kronecker is not None:
        n = model.n_dof
        identity = jnp.eye(n, dtype=masses[0].dtype)
        for name, dense, reference in (("product", jax.vmap(kronecker.mv)(identity), masses[0]),
                                       ("inverse", jax.vmap(kronecker.solve)(masses[0]), identity)):
            if _differ(dense, reference) > 1e-6:
                fail("kronecker_mass", f"its {name} differs from the assembled mass by {_differ(dense, reference):.2e} "
                                       "(relative)")
    if jacobians:
        rows = model.constraint_rows(states[0][0])
        if _differ(rows.dense(), jacobians[0]) > RELATIVE:
            fail("constraint_rows", f"differ from g_q by {_differ(rows.dense(), jacobians[0]):.2e} (relative)")
        dense = np.asarray(rows.dense())
        if not rows.orthonormal() or np.abs(dense @ dense.T - np.eye(dense.shape[0])).max() > RELATIVE:
            fail("constraint_rows", "must be orthonormal: unit norm, and no coordinate shared but by a node's "
                                    "orthogonal rows (one contact a node, or a pinned node's axes)")


def _check_friction(model: Model, qs, fail) -> None:
    """The friction structure: nf normal rows, each a distinct unilateral row,
    nf coefficients >= 0, a tangent Jacobian of nf · d rows, d = 1 or 2,
    the same at every state where the constraints are declared affine (a
    constant velocity iteration matrix holds its product with g_T)."""
    q = qs[0]
    nf, d, nb, nc = model.n_friction, model.friction_dim, model.n_bilateral, model.n_constraints
    normals = model.friction_normals
    if d not in (1, 2):
        fail("friction_dim", f"must be 1 (planar) or 2 (spatial) with frictional contacts, got {d}")
    if len(normals) != nf or len(set(normals)) != nf or not all(nb <= j < nc for j in normals):
        fail("friction_normals", f"must be {nf} distinct unilateral rows (in [{nb}, {nc})), got {normals}")
    mu = np.asarray(model.friction_coefficients)
    if mu.shape != (nf,) or not np.all(mu >= 0):
        fail("friction_coefficients", f"must be {nf} values >= 0, got {mu.tolist()}")
    shape = tuple(model.tangent_jacobian(q).shape)
    if shape != (nf * d, model.n_dof):
        fail("tangent_jacobian", f"has shape {shape}, where the declared sizes say {(nf * d, model.n_dof)}")
    if model.linear_constraints:
        tangents = [model.tangent_jacobian(x) for x in qs]
        change = max(_differ(T, tangents[0]) for T in tangents[1:])
        if change > RELATIVE:
            fail("linear_constraints", f"declared True, but the tangent Jacobian g_T changes with q (by "
                                       f"{change:.2e}, relative)")



CAPABILITIES: tuple[Capability, ...] = (
    Capability("velocity_dependent_force", lambda m: not m.velocity_dependent_force, _force_without_v),
    Capability("constant_mass", lambda m: m.constant_mass, _constant_mass),
    Capability("linear_force", lambda m: m.linear_force, _linear_force),
    Capability("linear_constraints", lambda m: m.linear_constraints and m.n_constraints > 0, _linear_constraints),
    Capability("friction", lambda m: m.n_friction > 0, lambda m, s, fail: _check_friction(m, [q for q, _ in s.states],
                                                                                         fail)),
    Capability("matrix_free", lambda m: m.matrix_free, lambda m, s, fail: _check_matrix_free(
        m, s.states, s.masses, s.stiffness, s.jacobians, fail)),
    Capability("bandwidth", lambda m: m.bandwidth is not None, _bandwidth),
    Capability("body_coupling", lambda m: m.body_coupling is not None, _body_coupling),
    Capability("energy", lambda m: m.has_energy, _energy),
)
"""Each structure flag and capability :func:`check_model` checks where a
model declares it, in this order (the first contradiction is raised)."""

__all__ = ["CAPABILITIES", "Capability", "check_model"]
