"""What every time-stepping scheme shares: the carried state and the scheme
interface (the operators a scheme prepares are in
:mod:`~nsga_jax._integrators.operators`, the per-step record in
:mod:`~nsga_jax._integrators.records`).

Records are physical: λ̃ [N], ν [N s²] and the impulse Λ [N s] (Λ/h is the
mean contact force over the step).
"""

from __future__ import annotations

import abc
from typing import ClassVar, cast

import equinox as eqx
import jax

from .._custom_types import Scalar, ScalarLike, Vector
from .._models.base import Model
from .._util import as_float
from .operators import MatrixKinds, Operators
from .records import StepOutput
from .subproblem_inputs import NewtonTolerances

# --------------------------------------------------------------------------- data


class StepState(eqx.Module):
    """What a scheme carries from step to step.

    t [s]; q, v (n,): coordinates and velocities; vd (n,): smooth acceleration
    v̇̃; a (n,): generalized-α pseudo-acceleration (both zero for Moreau–Jean);
    factorisations: the iteration-matrix factorisations a scheme keeps for its
    next step (one per sub-problem, ``None`` where it keeps none; see
    :attr:`~nsga_jax._integrators.ds.DS.reuse_min_dof`), or ``None``;
    closed (nu,) bool: the unilateral contacts the step closed (active in
    its position correction), which a step that locates impact instants
    does not locate again (:mod:`~nsga_jax._integrators.impact_instants`), or
    ``None`` where the scheme does not locate them; multipliers: the
    position correction's and the velocity jump's multipliers of the last
    step ((m,) each), Newton's start in the next with
    ``DS(warm_start=True)``, or ``None`` (each sub-problem starts at zero);
    persistent (nc,) bool: the unilateral contacts the next step's smooth
    motion holds (``DS(persistent_contacts=True)``,
    :mod:`~nsga_jax._integrators.persistent_contacts`), or ``None``.
    """

    t: Scalar
    q: Vector
    v: Vector
    vd: Vector
    a: Vector
    factorisations: tuple | None = None
    closed: jax.Array | None = None
    multipliers: tuple[jax.Array, jax.Array] | None = None
    persistent: jax.Array | None = None


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
    (:class:`~nsga_jax._integrators.records.NewtonRecord`)."""

    @property
    def tolerances(self) -> NewtonTolerances:
        """The Newton settings every sub-problem of a step is given."""
        # tol_r and tol_f are typed as what __init__ accepts; their converter (as_float) made them arrays
        return NewtonTolerances(cast(jax.Array, self.tol_r), cast(jax.Array, self.tol_f), self.max_iter)

    @abc.abstractmethod
    def matrix_kinds(self, model: Model) -> MatrixKinds:
        """The kinds of the smooth, position and velocity iteration matrices
        :meth:`prepare` builds for ``model`` (static: nothing is evaluated;
        :mod:`~nsga_jax._integrators.iteration_matrix`)."""

    @abc.abstractmethod
    def prepare(self, model: Model, h: Scalar, t0: Scalar) -> Operators:
        """The operators for this model and step size: the model's terms and
        the iteration matrices, what is constant computed here (run once,
        outside the loop; :mod:`~nsga_jax._integrators.operators`)."""

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
