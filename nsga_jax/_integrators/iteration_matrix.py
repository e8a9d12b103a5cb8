"""How each Newton sub-problem solves with its iteration matrix (paper eqs. 47-50).

The iteration matrix of a sub-problem is bordered (:mod:`~nsga_jax._integrators.linalg`);
what a Newton correction factors is its top-left block A:

- smooth motion (eq. 47, its constant form 50): ``S_t^s = c_vd M + C + c_q (K + K_M - K_g)``;
- position correction (eq. 48): ``S_t^p = M + h² K - K_g`` (DSn and CS: ``M - K_g``);
- velocity jump (eq. 49): ``S_t^v = M + h C`` (DSn and CS: ``M``);

with c_vd = dv̇̃/dṽ and c_q = dq̃/dṽ of (44b-c), K_M the inertia stiffness
and K_g the constraint curvature (both zero in the constant forms). How a
sub-problem solves with A is an object, chosen at trace time from the
model's static structure (:func:`~nsga_jax._integrators.operators.matrix_kinds`):

- :class:`ConstantInverse`: A constant (constant mass, linear force, affine
  constraints where A holds their curvature), inverted once per step size
  with its products A^{-1} G^T;
- :class:`ConstantTridiagonal`: the same for a chain of half-bandwidth 1,
  factorised by block elimination (:class:`~nsga_jax._integrators.linalg.Tridiagonal`);
- :class:`Refactored`: A evaluated and LU-factored at every Newton iteration;
- :class:`Held`: A's LU factors kept from iteration to iteration and from
  step to step, refactored only when an update made with them converges too
  slowly (modified Newton, :func:`~nsga_jax._integrators.newton.newton`).

Each kind says statically whether it is constant (``is_constant``) and
whether its factorisation is held (``is_held``); :meth:`AbstractIterationMatrix.factored`
gives what a Newton correction solves with at an iterate: the constant matrix
itself, or a fresh :class:`~nsga_jax._integrators.linalg.Factorisation`.
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Matrix, Scalar, Vector
from .linalg import AbstractFactorisation, Factorisation, Tridiagonal, band_matrix

BuildMatrix = Callable[[], tuple[Matrix, Scalar, Scalar]]
"""``() -> (A, ||K||, ||C||)``: a sub-problem's top-left block at the current
iterate and the Frobenius norms of the tangents it holds (evaluated only by
the kinds that are not constant)."""

BuildElements = Callable[[], tuple[Any, Scalar, Scalar, Any]]
"""``() -> (A, ||K||, ||C||, preconditioner)``: a sub-problem's top-left
block as node blocks (:class:`~nsga_jax._blocks.NodeBlockMatrix`) and what
preconditions it, for the kinds that never assemble it
(:mod:`~nsga_jax._integrators.krylov`)."""


class AbstractIterationMatrix(eqx.Module):
    """How one sub-problem solves with its iteration matrix's top-left block A.

    Class attributes (known at trace time):
        is_constant: A is the same at every iterate and step (computed once per step size).
        is_held: A's factorisation is carried from iteration to iteration and
            from step to step (in :attr:`~nsga_jax._integrators.base.StepState.factorisations`).
    """

    is_constant: ClassVar[bool]
    is_held: ClassVar[bool] = False

    @abc.abstractmethod
    def factored(self, build: BuildMatrix, elements: BuildElements | None = None) -> AbstractFactorisation:
        """What a Newton correction at the current iterate solves with;
        ``build`` gives A there (called only when A is not constant), and
        ``elements`` its element blocks (a matrix-free model's sub-problems)."""


class _AbstractConstant(AbstractIterationMatrix, AbstractFactorisation):
    """A constant A, factorised once per step size: it is its own factorisation.

    ``inverse_Gt``: A^{-1} G^T (n, m) for the sub-problem's constraint rows
    when the constraints are affine, else ``None`` (then formed at each solve).
    """

    inverse_Gt: eqx.AbstractVar[jax.Array | None]
    is_constant: ClassVar[bool] = True

    def factored(self, build: BuildMatrix, elements: BuildElements | None = None) -> AbstractFactorisation:
        return self

    def solve_with_constraints(self, rhs: Vector, G: jax.Array) -> tuple[Vector, jax.Array]:
        if self.inverse_Gt is None:
            return super().solve_with_constraints(rhs, G)
        return self.solve(rhs), self.inverse_Gt


class ConstantInverse(_AbstractConstant):
    """A constant A through its dense inverse: a solve is one product, n² multiply-adds.

    Attributes:
        inverse: A^{-1}, shape (n, n).
        inverse_Gt: A^{-1} G^T, shape (n, m), or ``None`` (constraints not affine).
        K_norm, C_norm: ||K||, ||C|| of the linear force (round-off floor).
    """

    inverse: Matrix
    inverse_Gt: jax.Array | None
    K_norm: Scalar
    C_norm: Scalar

    @classmethod
    def of(cls, A: Matrix, G: jax.Array | None, K_norm: Scalar, C_norm: Scalar) -> "ConstantInverse":
        """Invert A and precompute A^{-1} G^T for the rows G (m, n), unless ``G`` is ``None``."""
        inverse = jnp.linalg.inv(A)
        return cls(inverse=inverse, inverse_Gt=None if G is None else inverse @ G.T, K_norm=K_norm, C_norm=C_norm)

    def solve(self, rhs: jax.Array, bound: Scalar | None = None) -> jax.Array:
        return self.inverse @ rhs


class ConstantTridiagonal(_AbstractConstant):
    """A constant tridiagonal A (a chain of half-bandwidth 1) through its block
    elimination: a solve is about 2 n^{1.5} multiply-adds.

    Attributes:
        elimination: the block elimination of A, :class:`~nsga_jax._integrators.linalg.Tridiagonal`.
        inverse_Gt: A^{-1} G^T, shape (n, m), or ``None`` (constraints not affine).
        K_norm, C_norm: ||K||, ||C|| of the linear force (round-off floor).
    """

    elimination: Tridiagonal
    inverse_Gt: jax.Array | None
    K_norm: Scalar
    C_norm: Scalar

    @classmethod
    def of(cls, A: Matrix, G: jax.Array | None, K_norm: Scalar, C_norm: Scalar) -> "ConstantTridiagonal":
        """Factorise the tridiagonal A (n, n) and precompute A^{-1} G^T for the
        rows G (m, n), unless ``G`` is ``None``."""
        elimination = Tridiagonal.of(band_matrix(A, 1))
        return cls(elimination=elimination, inverse_Gt=None if G is None else elimination.solve(G.T),
                   K_norm=K_norm, C_norm=C_norm)

    def solve(self, rhs: jax.Array, bound: Scalar | None = None) -> jax.Array:
        return self.elimination.solve(rhs)


class Refactored(AbstractIterationMatrix):
    """A evaluated and LU-factored at every Newton iteration (Newton's method)."""

    is_constant: ClassVar[bool] = False

    def factored(self, build: BuildMatrix, elements: BuildElements | None = None) -> AbstractFactorisation:
        return Factorisation.of(*build())


class Held(AbstractIterationMatrix):
    """A's LU factors held between iterations and steps and refactored when
    they stop contracting (modified Newton); :meth:`empty` is the placeholder
    a run starts with."""

    is_constant: ClassVar[bool] = False
    is_held: ClassVar[bool] = True

    def factored(self, build: BuildMatrix, elements: BuildElements | None = None) -> AbstractFactorisation:
        return Factorisation.of(*build())

    @staticmethod
    def empty(n: int, dtype) -> Factorisation:
        """The factorisation a run starts with (nothing factored yet)."""
        return Factorisation.empty(n, dtype)

    @staticmethod
    def empty_like(model, dtype) -> Factorisation:
        """:meth:`empty` for ``model``'s n coordinates."""
        return Factorisation.empty(model.n_dof, dtype)
