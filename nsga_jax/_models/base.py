"""The semi-discrete model: what the time integrator needs to know of a system.

A model describes the equations of motion (paper eq. 1)

    M(q) dv - g_q(q)^T di = f(q, v, t) dt,
    g^B(q) = 0                       (bilateral constraints),
    g^U(q) >= 0, Newton impact law   (unilateral constraints, restitution e),

through a handful of pure functions. Everything numeric is a pytree leaf (so a
model can be differentiated and batched); everything structural (sizes, which
terms are constant or linear) is a static field, known at trace time, so the
integrator compiles only what a scene needs.

Conventions: ``n`` coordinates, ``nb`` bilateral and ``nu`` unilateral
constraints, ``nc = nb + nu``; the constraint vector is ``[g^B; g^U]``
(bilaterals first). ``force`` returns f, the *right-hand side* (external +
internal + damping + complementary inertia); its tangents are
``K = -df/dq`` and ``C = -df/dv``.
"""

from __future__ import annotations

import abc
from typing import ClassVar

import jax
import jax.numpy as jnp
from jax import lax

from .._custom_types import ConstraintMatrix, ConstraintVector, Matrix, Scalar, Vector
from .._results import ConfigError
from .._validation import Range, integer
from .capabilities import ElementBlocks, EnergyMonitor, FrictionalContacts
from .coupling import BodyCoupling


def count_rule(name: str, value, lo: int = 1) -> str | None:
    """A static count (elements, nodes) must be an integer >= lo."""
    try:
        integer(name, value, lo)
    except ConfigError as error:
        return str(error)
    return None


class Model(FrictionalContacts, ElementBlocks, EnergyMonitor):
    """Abstract base class of every model: what every model gives the integrator.

    Subclasses implement :meth:`mass`, :meth:`force`, and where they have
    constraints :meth:`bilateral`, :meth:`unilateral` and :attr:`restitution`.
    They declare their sizes and structure through the abstract properties
    below (plain Python values, never arrays).

    The tangents default to ``jax.jacfwd`` of the global functions; models
    assembled from elements override :meth:`tangents` with element-level
    tangents (see :mod:`nsga_jax._assembly`).

    What a model may have beyond this (frictional contacts, element blocks
    for the matrix-free path, an energy to monitor) is one capability each,
    in :mod:`nsga_jax._models.capabilities`, whose defaults mean "not this".
    """

    ranges: ClassVar[dict[str, Range]] = {}
    """Allowed range of named float fields (every element of an array field),
    checked with concrete values by :func:`~nsga_jax.simulate` before tracing;
    every float field must be finite in any case."""

    def __check_init__(self):
        """Refuse, at construction, what the model's physics cannot mean
        (:func:`~nsga_jax._validation.check_model_fields`): non-finite fields,
        fields out of their ranges, broken :meth:`invalid` rules."""
        from .._validation import check_model_fields

        check_model_fields(self)

    def invalid(self) -> str | None:
        """A rule on concrete values that ``ranges`` cannot state (e.g. a positive
        definite inertia tensor): the broken rule's message, or ``None``."""
        return None

    # ----------------------------------------------------------- structure
    @property
    @abc.abstractmethod
    def n_dof(self) -> int:
        """Number of generalised coordinates ``n``."""

    @property
    def n_bilateral(self) -> int:
        """Number of bilateral constraints ``nb``."""
        return 0

    @property
    def n_unilateral(self) -> int:
        """Number of unilateral constraints ``nu``."""
        return 0

    @property
    def n_constraints(self) -> int:
        return self.n_bilateral + self.n_unilateral

    @property
    def constant_mass(self) -> bool:
        """``True`` when M does not depend on q (it is then evaluated once)."""
        return False

    @property
    def linear_force(self) -> bool:
        """``True`` when f is affine in (q, v) with constant K and C."""
        return False

    @property
    def velocity_dependent_force(self) -> bool:
        """``False`` when f does not depend on v (no damping, no gyroscopic terms):
        C = 0 is then never formed and f* is evaluated once per velocity sub-problem."""
        return True

    @property
    def linear_constraints(self) -> bool:
        """``True`` when every constraint is affine in q (constant g_q)."""
        return False

    @property
    def bandwidth(self) -> int | None:
        """Half-bandwidth b of M, K and C when they are banded (``A[i, j] = 0``
        for ``|i - j| > b``, as in a 1D chain of elements), ``None`` otherwise.
        A linear model with a narrow band has its products with M and K done
        on the band (:func:`~nsga_jax._integrators.linalg.band_product`), so a
        declared band the matrices do not have gives wrong products: declare
        it from the element-to-dof map (the bar's test checks its band against
        the assembled M and K)."""
        return None

    @property
    def body_coupling(self) -> BodyCoupling | None:
        """Which coordinates M, K, C and the constraint rows couple, body by
        body (:class:`~nsga_jax._models.coupling.BodyCoupling`), or ``None``
        (any coordinate with any). A system of bodies declares it from its
        parts; a chain's or tree's iteration matrices are then solved by
        block elimination (:mod:`~nsga_jax._integrators.structured`)."""
        return None

    @property
    @abc.abstractmethod
    def mbar(self) -> Scalar | float:
        """Characteristic mass m̄ [kg] used to scale the multipliers (paper §3.3.6)."""

    # --------------------------------------------------------------- physics
    @abc.abstractmethod
    def mass(self, q: Vector) -> Matrix:
        """Mass matrix M(q), shape (n, n) [kg or kg m²]."""

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        """M(q) @ x, shape (n,). Element models override it with a matrix-free
        element-level product (O(n) instead of a dense O(n²) product)."""
        return self.mass(q) @ x

    @abc.abstractmethod
    def force(self, q: Vector, v: Vector, t: Scalar) -> Vector:
        """Force vector f(q, v, t), shape (n,) [N]."""

    def tangents(self, q: Vector, v: Vector, t: Scalar) -> tuple[Matrix, Matrix]:
        """Stiffness ``K = -df/dq`` and damping ``C = -df/dv``, each (n, n)."""
        K = -jax.jacfwd(self.force, argnums=0)(q, v, t)
        C = -jax.jacfwd(self.force, argnums=1)(q, v, t)
        return K, C

    def bilateral(self, q: Vector) -> ConstraintVector:
        """Bilateral constraints g^B(q), shape (nb,) [m]; zero when satisfied."""
        return jnp.zeros((0,), dtype=q.dtype)

    def unilateral(self, q: Vector) -> ConstraintVector:
        """Unilateral gaps g^U(q), shape (nu,) [m]; admissible when >= 0."""
        return jnp.zeros((0,), dtype=q.dtype)

    @property
    def restitution(self) -> ConstraintVector:
        """Newton restitution coefficients e, shape (nu,), each in [0, 1]."""
        return lax.full((self.n_unilateral,), 0.0)  # weakly typed: takes the run's precision

    # ------------------------------------------------ derived (not overridden)
    def constraints(self, q: Vector) -> ConstraintVector:
        """All constraints ``[g^B; g^U]``, shape (nc,)."""
        return jnp.concatenate([self.bilateral(q), self.unilateral(q)])

    def constraint_jacobian(self, q: Vector) -> ConstraintMatrix:
        """g_q = d[g^B; g^U]/dq, shape (nc, n)."""
        return jax.jacfwd(self.constraints)(q)

    def bilateral_jacobian(self, q: Vector) -> ConstraintMatrix:
        """g_q^B = d g^B/dq, shape (nb, n)."""
        return jax.jacfwd(self.bilateral)(q)

    def constraint_curvature(self, q: Vector, mu: ConstraintVector) -> Matrix:
        """d(g_q(q)^T mu)/dq at fixed mu (mu over all nc constraints), shape (n, n);
        zero for affine constraints."""
        if self.linear_constraints or self.n_constraints == 0:
            return jnp.zeros((self.n_dof, self.n_dof), dtype=q.dtype)
        return jax.jacfwd(lambda x: self.constraint_jacobian(x).T @ mu)(q)

    def velocity_constraint_gradient(self, q: Vector, v: Vector, bilateral_only: bool = False) -> ConstraintMatrix:
        """G^s = d(g_q(q) v)/dq at fixed v, shape (nc, n), or (nb, n) with
        ``bilateral_only`` (paper eq. 50); zero for affine constraints."""
        rows = self.n_bilateral if bilateral_only else self.n_constraints
        if self.linear_constraints:
            return jnp.zeros((rows, self.n_dof), dtype=q.dtype)
        fn = self.bilateral if bilateral_only else self.constraints
        return jax.jacfwd(lambda x: jax.jacfwd(fn)(x) @ v)(q)

    def inertia_stiffness(self, q: Vector, a: Vector) -> Matrix:
        """d(M(q) a)/dq at fixed a, shape (n, n); zero for a constant mass."""
        if self.constant_mass:
            return jnp.zeros((self.n_dof, self.n_dof), dtype=q.dtype)
        return jax.jacfwd(lambda x: self.mass(x) @ a)(q)

