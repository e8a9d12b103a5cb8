"""How a differentiable run is differentiated: the ``adjoint=`` of :func:`~nsga_jax.integrate`.

Every step of every scheme with an implicit adjoint (DS, DSn, MJ) is
differentiable as it is: each converged Newton sub-problem carries the
implicit derivative of its solution as a custom JVP
(:func:`~nsga_jax._integrators.newton.solve`), so a run that nobody
differentiates computes exactly what :func:`~nsga_jax.simulate` computes,
and a differentiated one never unrolls Newton iterations. What an adjoint
chooses is which derivative a step carries:

- :class:`DiscreteAdjoint` (the default): the exact derivative of the
  time-stepping map, impacts held at their steps;
- :class:`ImpactTimeAdjoint`: at each step where a contact closes, the
  derivative of the step rebuilt in continuous time, which sees the impact
  instant move (:mod:`nsga_jax._impact_time`).

Values are the same with both. The time loop calls, per run and per step,

``adjoint.init(model, q0) -> extra``
    what the adjoint carries from step to step (a pytree);
``adjoint.step(scheme, model, ops, state, extra, h) -> (state, record, extra)``
    one step of ``scheme`` with this adjoint's derivative.
"""

from __future__ import annotations

import abc
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from ._custom_types import Scalar, Vector
from ._impact_time import initially_active, with_impact_time_sensitivity
from ._integrators.base import AbstractScheme, StepState
from ._integrators.cs import CS
from ._integrators.operators import Operators
from ._integrators.records import StepOutput
from ._models.base import Model
from ._results import ConfigError

ADJOINT_KINDS = "an adjoint instance: nsga_jax.DiscreteAdjoint() or nsga_jax.ImpactTimeAdjoint()"
"""What ``adjoint=`` accepts, for error messages."""


def refuse_without_implicit_adjoint(scheme: AbstractScheme) -> None:
    """Raise :class:`~nsga_jax.ConfigError` for a scheme whose step has no
    implicit adjoint: CS iterates its three sub-problems together, and its
    coupled loop has no converged sub-problem to differentiate."""
    if isinstance(scheme, CS):
        raise ConfigError("CS is not differentiable here (its coupled iteration has no implicit adjoint); "
                          "use DS, DSn or MJ for gradients")


class AbstractAdjoint(eqx.Module):
    """Which derivative the steps of a differentiable run carry (see the module docstring)."""

    @abc.abstractmethod
    def init(self, model: Model, q0: Vector) -> Any:
        """What this adjoint carries from step to step, at t0 (a pytree)."""

    @abc.abstractmethod
    def step(self, scheme: AbstractScheme, model: Model, ops: Operators, state: StepState, extra: Any,
             h: Scalar) -> tuple[StepState, StepOutput, Any]:
        """One step of ``scheme`` of size h [s] from ``state``: the new state,
        the step's record and the new ``extra``. Raises
        :class:`~nsga_jax.ConfigError` for a scheme without an implicit adjoint."""


class DiscreteAdjoint(AbstractAdjoint):
    """The exact derivative of the time-stepping map (the default).

    Each converged Newton sub-problem is differentiated by the implicit
    function theorem at its solution, its active set frozen; impacts stay at
    the steps where the scheme put them while a parameter moves, so through an
    impact the gradient is that of the piece of the (piecewise smooth) loss
    the parameters are on. Carries nothing between steps.
    """

    def init(self, model: Model, q0: Vector) -> tuple[()]:
        return ()

    def step(self, scheme: AbstractScheme, model: Model, ops: Operators, state: StepState, extra: tuple[()],
             h: Scalar) -> tuple[StepState, StepOutput, tuple[()]]:
        refuse_without_implicit_adjoint(scheme)
        new, out = scheme.step(model, ops, state, h)
        return new, out, extra


class ImpactTimeAdjoint(AbstractAdjoint):
    """The derivative that sees impact instants move.

    Steps without a closing contact carry the discrete derivative; at a step
    where a contact closes (active in the step's velocity problem and not in
    the previous step's, approaching at t_n), the state keeps the scheme's
    value and takes the derivative of the step rebuilt in continuous time
    (:func:`~nsga_jax._impact_time.with_impact_time_sensitivity`), which adds
    the saltation term of the moving impact instant. With
    ``DS(impact_instants=True)`` a step split at its located instants keeps
    the discrete derivative, which already moves them with the parameters;
    an impact that a paper step takes (a contact closed at the start,
    chatter) is rebuilt as above. Carries the contacts' last velocity active
    set, shape (nu,).
    """

    def init(self, model: Model, q0: Vector) -> jax.Array:
        if model.n_unilateral == 0:
            return jnp.zeros((0,), bool)
        return initially_active(model, q0)

    def step(self, scheme: AbstractScheme, model: Model, ops: Operators, state: StepState, extra: jax.Array,
             h: Scalar) -> tuple[StepState, StepOutput, jax.Array]:
        refuse_without_implicit_adjoint(scheme)
        law = getattr(scheme, "impact_law", "newton")
        if model.n_friction and law != "newton":
            raise ConfigError(f"ImpactTimeAdjoint rebuilds an impact with Newton's law, not the impact_law = "
                              f"{law!r} of {type(scheme).__name__} (with friction they differ); use "
                              "DiscreteAdjoint(), the derivative of the energetic law as it runs")
        new, out = scheme.step(model, ops, state, h)
        if model.n_unilateral == 0:
            return new, out, extra
        # a step split at its located instants (DS(impact_instants=True)) is differentiated as it ran
        located = out.instants > 0 if getattr(scheme, "impact_instants", False) else False
        with jax.named_scope("impact_time_sensitivity"):
            new, out = with_impact_time_sensitivity(model, ops, state, new, out, h, extra, located)
        return new, out, out.active_velocity[model.n_bilateral:]


ADJOINTS: dict[str, type[AbstractAdjoint]] = {"discrete": DiscreteAdjoint, "event": ImpactTimeAdjoint}
"""The adjoints by the names the command line gives them."""


def adjoint_named(name: str) -> AbstractAdjoint:
    """The adjoint called ``name`` on the command line (``"discrete"`` or ``"event"``)."""
    if name not in ADJOINTS:
        raise ConfigError(f"adjoint must be one of {', '.join(map(repr, ADJOINTS))}, got {name!r}")
    return ADJOINTS[name]()
