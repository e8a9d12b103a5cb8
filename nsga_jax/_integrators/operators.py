"""A run's operators: the model's terms and the three sub-problems' iteration
matrices, each as an object whose kind the model's structure decides at
trace time, with what is constant computed once per step size (outside the
time loop).

A scheme's ``prepare`` calls :func:`prepare_operators` with the kinds of
:func:`matrix_kinds` and the top-left blocks of its iteration matrices
(eqs. 47-50). ``fast_paths=False`` keeps nothing constant
(:func:`generic_operators`): every term is evaluated and every matrix
factored at every iteration.
"""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Matrix, Scalar, ScalarLike
from .._models.base import Model
from .contact_rows import velocity_rows
from .iteration_matrix import (
    AbstractIterationMatrix,
    ConstantInverse,
    ConstantTridiagonal,
    Held,
    Refactored,
)
from .krylov import (
    KRYLOV_KINDS,
    KrylovConstant,
    KrylovFresh,
    KrylovHeld,
    KrylovOperator,
    kronecker_mass,
    linear_tolerance,
    mass_preconditioner,
)
from .linalg import band_matrix
from .model_terms import (
    AbstractConstraintJacobian,
    AbstractForceTerm,
    AbstractMass,
    BandedLinearForce,
    BandedMass,
    ConstantJacobian,
    ConstantMass,
    ElementMass,
    LinearForce,
    NonlinearForce,
    RowsJacobian,
    VaryingJacobian,
    VaryingMass,
)
from .structured import Structured, structured_applies

MatrixKinds = tuple[type[AbstractIterationMatrix], type[AbstractIterationMatrix], type[AbstractIterationMatrix]]
"""The kinds of the smooth, position and velocity iteration matrices."""

TopLeft = Callable[[Matrix, Matrix, Matrix], Matrix]
"""``(M, K, C) -> A``: the constraint-free block of an iteration matrix."""


class Operators(eqx.Module):
    """What a step uses of the model and its iteration matrices, for one step size.

    Attributes:
        mass: M(q) (:class:`~nsga_jax._integrators.model_terms.ConstantMass`,
            ``BandedMass`` or ``VaryingMass``).
        force: f and its tangents K, C (``LinearForce``, ``BandedLinearForce``
            or ``NonlinearForce``).
        constraints: g_q (``ConstantJacobian`` for affine constraints, or ``VaryingJacobian``).
        smooth, position, velocity: the iteration matrices of the three
            sub-problems (eqs. 47-49; :mod:`~nsga_jax._integrators.iteration_matrix`);
            a scheme without such a sub-problem has a ``Refactored`` it never uses.
    """

    mass: AbstractMass
    force: AbstractForceTerm
    constraints: AbstractConstraintJacobian
    smooth: AbstractIterationMatrix
    position: AbstractIterationMatrix
    velocity: AbstractIterationMatrix


def banded(model: Model) -> bool:
    """Whether a model's constant M and K are worked with on their band: a
    linear model with constant mass that declares a half-bandwidth b with
    2b + 1 <= n / 8 (a 1D chain); wider bands gain nothing over the dense or
    element-by-element products."""
    b = model.bandwidth
    return (b is not None and model.constant_mass and model.linear_force
            and 8 * (2 * b + 1) <= model.n_dof)


def uses_matrix_free(model: Model, fast_paths: bool, krylov_min_dof: int | None) -> bool:
    """Whether a run of ``model`` assembles no matrix (static): fast paths,
    a matrix-free model and at least ``krylov_min_dof`` coordinates; a
    banded one (a chain, already solved on its band in O(n), :func:`banded`)
    only with ``krylov_min_dof = 0``."""
    return (fast_paths and krylov_min_dof is not None and model.matrix_free
            and model.n_dof >= krylov_min_dof and (krylov_min_dof == 0 or not banded(model)))


def matrix_kinds(model: Model, needs_constant_G: tuple[bool, bool, bool],
                 present: tuple[bool, bool, bool] = (True, True, True), enabled: bool = True,
                 hold: bool = False, krylov: bool = False,
                 holds_stiffness: tuple[bool, bool, bool] = (True, True, False),
                 smooth_contacts: bool = False) -> MatrixKinds:
    """The kinds of the smooth, position and velocity iteration matrices,
    from the model's static structure alone (no array is evaluated).

    A matrix is constant when the model has a constant mass and a linear
    force, and, where it holds the constraints' curvature
    (``needs_constant_G``; the smooth one only through the bilateral rows),
    affine constraints; a chain of half-bandwidth 1 then solves it by block
    elimination. A system of bodies whose coupling orders its bordered
    matrix into enough blocks (:mod:`~nsga_jax._integrators.structured`;
    frictionless) solves every present sub-problem by block elimination.
    Otherwise a matrix is refactored at every iteration, or held between
    iterations and steps when ``hold``. ``present``: the scheme has
    that sub-problem (the position and velocity ones only with constraints).
    ``enabled=False`` (the generic path) refactors everything.
    ``smooth_contacts``: the smooth sub-problem has every constraint row
    (:mod:`~nsga_jax._integrators.persistent_contacts`), not the bilateral ones only.

    ``krylov`` (a :attr:`~nsga_jax._models.Model.matrix_free` model only):
    no matrix is assembled (:mod:`~nsga_jax._integrators.krylov`); a block is
    constant when it holds no stiffness (``holds_stiffness``: the velocity
    jump's M + h C with C = 0) or the force is linear, else evaluated as
    element blocks at every iteration, or held when ``hold``.
    """
    nb, nc = model.n_bilateral, model.n_constraints
    present = (present[0], present[1] and nc > 0, present[2] and nc > 0)
    smooth_rows = nc if smooth_contacts else nb
    needs = (needs_constant_G[0] and smooth_rows > 0, needs_constant_G[1], needs_constant_G[2])
    constant_G = model.linear_constraints and nc > 0
    linear = enabled and model.constant_mass and model.linear_force
    tridiagonal = banded(model) and model.bandwidth == 1

    if krylov and enabled and model.matrix_free:
        return tuple(  # type: ignore[return-value]
            (KrylovConstant if (model.linear_force or not stiff) else KrylovHeld if hold else KrylovFresh)
            if p else Refactored
            for p, stiff in zip(present, holds_stiffness))

    def kind(is_present: bool, needs_G: bool, rows: int) -> type[AbstractIterationMatrix]:
        if is_present and linear and (constant_G or not needs_G) and tridiagonal:
            return ConstantTridiagonal
        if is_present and enabled and model.n_friction == 0 and structured_applies(model.body_coupling, rows):
            return Structured
        if is_present and linear and (constant_G or not needs_G):
            return ConstantInverse
        return Held if (is_present and enabled and hold) else Refactored

    return kind(present[0], needs[0], smooth_rows), kind(present[1], needs[1], nc), kind(present[2], needs[2], nc)


def generic_operators() -> Operators:
    """Nothing constant: every term evaluated and every matrix factored at every iteration."""
    return Operators(mass=VaryingMass(), force=NonlinearForce(), constraints=VaryingJacobian(),
                     smooth=Refactored(), position=Refactored(), velocity=Refactored())


def prepare_operators(model: Model, t0: Scalar, kinds: MatrixKinds,
                      top_lefts: tuple[TopLeft | None, TopLeft | None, TopLeft | None],
                      enabled: bool = True, tol_r: ScalarLike | None = None,
                      smooth_contacts: bool = False) -> Operators:
    """Evaluate what the model's structure makes constant (M, K and C, g_q,
    their bands) and factorise the iteration matrices that ``kinds`` (from
    :func:`matrix_kinds`) say are constant, from their ``top_lefts``
    (smooth, position, velocity; ``None`` for a sub-problem the scheme does
    not have). The smooth block couples only to the bilateral rows of g_q,
    the others to all rows, and the velocity one, with friction, to the
    tangential rows g_T too (and so does the smooth one with ``smooth_contacts``,
    :mod:`~nsga_jax._integrators.persistent_contacts`). ``enabled=False``: :func:`generic_operators`.
    Kinds that are never assembled (:mod:`~nsga_jax._integrators.krylov`,
    solving to eq. 51's ``tol_r``) get :func:`matrix_free_operators`.
    """
    if not enabled:
        return generic_operators()
    if any(issubclass(kind, KRYLOV_KINDS) for kind in kinds):
        assert tol_r is not None, "solving without assembling needs eq. 51's tol_r"
        return matrix_free_operators(model, t0, kinds, top_lefts, tol_r)
    n, nb, nc = model.n_dof, model.n_bilateral, model.n_constraints
    real = jnp.result_type(t0, float)  # the run's precision, that of t0 (float32 or float64)
    zeros = jnp.zeros((n,), real)
    b = model.bandwidth if banded(model) else None
    mass: AbstractMass = VaryingMass()
    M = K = C = None
    if model.constant_mass:
        M = model.mass(zeros)
        M_norm = jnp.linalg.norm(M)
        mass = ConstantMass(M, M_norm) if b is None else BandedMass(M, M_norm, band_matrix(M, b))
    force: AbstractForceTerm = NonlinearForce()
    K_norm = C_norm = jnp.zeros((), real)
    if model.linear_force:
        K, C = model.tangents(zeros, zeros, t0)
        if not model.velocity_dependent_force:
            C = jnp.zeros_like(K)
        K_norm, C_norm = jnp.linalg.norm(K), jnp.linalg.norm(C)
        force = (LinearForce(K, C, K_norm, C_norm) if b is None else
                 BandedLinearForce(K, C, K_norm, C_norm, band_matrix(K, b),
                                   band_matrix(C, b) if model.velocity_dependent_force else None,
                                   model.velocity_dependent_force))
    constraints: AbstractConstraintJacobian = VaryingJacobian()
    if model.linear_constraints and nc > 0:
        constraints = ConstantJacobian(model.constraint_jacobian(zeros), nb)

    def build(kind: type[AbstractIterationMatrix], top_left: TopLeft | None, rows: int,
              tangential: bool = False) -> AbstractIterationMatrix:
        if kind is Structured:
            assert model.body_coupling is not None  # matrix_kinds: structured_applies
            return Structured(model.body_coupling)
        if not issubclass(kind, (ConstantInverse, ConstantTridiagonal)):
            return kind()
        assert top_left is not None and M is not None and K is not None and C is not None  # matrix_kinds: linear
        G = constraints.G[:rows] if (isinstance(constraints, ConstantJacobian) and rows) else None
        if G is not None and tangential:  # the velocity sub-problems' rows: g_q and, with friction, g_T
            G = velocity_rows(model, zeros, G)
        return kind.of(top_left(M, K, C), G, K_norm, C_norm)

    smooth, position, velocity = (build(kind, top_left, rows, tangential)
                                  for kind, top_left, rows, tangential
                                  in zip(kinds, top_lefts, (nc if smooth_contacts else nb, nc, nc),
                                         (smooth_contacts, False, True)))
    return Operators(mass=mass, force=force, constraints=constraints,
                     smooth=smooth, position=position, velocity=velocity)


def matrix_free_operators(model: Model, t0: Scalar, kinds: MatrixKinds,
                          top_lefts: tuple[TopLeft | None, TopLeft | None, TopLeft | None],
                          tol_r: ScalarLike) -> Operators:
    """A matrix-free model's operators: its mass as element blocks, its rows
    node by node, the constant blocks as element blocks with their
    preconditioners. A top-left block A = top_left(M, K, C) is linear in its
    arguments, so its coefficients are read off by evaluating it on numbers."""
    real = jnp.result_type(t0, float)
    zeros = jnp.zeros((model.n_dof,), real)
    M = model.element_mass(zeros).node_blocks()
    kronecker = kronecker_mass(model, real)
    rtol = linear_tolerance(tol_r, real)
    constraints: AbstractConstraintJacobian = VaryingJacobian()
    if model.n_constraints:
        G = model.constraint_rows(zeros)
        assert G.orthonormal(), "a matrix-free model's rows share no coordinate"
        constraints = RowsJacobian(G, model.n_bilateral)

    def build(kind: type[AbstractIterationMatrix], top_left: TopLeft | None) -> AbstractIterationMatrix:
        if kind in (KrylovFresh, KrylovHeld):
            return kind(rtol)
        if kind is not KrylovConstant:
            return kind()
        assert top_left is not None
        c_m, c_k = top_left(1.0, 0.0, 0.0), top_left(0.0, 1.0, 0.0)  # type: ignore[arg-type]
        zero = jnp.zeros((), real)
        preconditioner = mass_preconditioner(kronecker, c_m)
        if not model.linear_force and preconditioner is not None:  # A = c_m M: its Kronecker form
            return KrylovConstant(KrylovOperator.of(preconditioner.mass, zero, zero, rtol, preconditioner))
        K = model.element_stiffness(zeros).node_blocks() if model.linear_force else M.combine(0.0, M, 0.0)
        return KrylovConstant(KrylovOperator.of(M.combine(c_m, K, c_k), K.frobenius_norm(), zero, rtol,
                                                preconditioner))

    smooth, position, velocity = (build(kind, top_left) for kind, top_left in zip(kinds, top_lefts))
    return Operators(mass=ElementMass(M, M.frobenius_norm(), kronecker), force=NonlinearForce(),
                     constraints=constraints, smooth=smooth, position=position, velocity=velocity)
