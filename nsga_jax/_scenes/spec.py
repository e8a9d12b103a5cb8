"""Scenes: a model, its initial state, named observables and solver settings
(:class:`Scene`), how a built-in or user scene is described and built
(:class:`SceneSpec`), and the registry of scenes by name."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .params import SOLVER_PARAMS, Param

if TYPE_CHECKING:  # the numerical modules load (with JAX) only when a scene is built or run
    from .._integrators.base import AbstractScheme
    from .._models.base import Model
    from .._solution import Solution


@dataclass
class Scene:
    """A ready-to-run system.

    Attributes:
        name: scene name.
        model: the :class:`~nsga_jax._models.Model`.
        q0, v0: initial coordinates and velocities (n,).
        parameters: the validated scene parameters.
        solver: the validated solver settings (scheme, h, t_end, rho_inf, ...).
        observables: ``Solution -> {name: array (rows,)}``, the scene's named
            observables (of a host or a pure :class:`~nsga_jax.Solution`).
        exact: ``ts -> {name: array}``, the exact solution of some observables
            where the scene has one (else ``None``).
    """

    name: str
    model: Model
    q0: np.ndarray
    v0: np.ndarray
    parameters: dict[str, Any]
    solver: dict[str, Any]
    observables: Callable[[Solution], dict[str, np.ndarray]]
    exact: Callable[[np.ndarray], dict[str, np.ndarray]] | None = None

    @property
    def spec(self) -> "SceneSpec":
        return REGISTRY[self.name]

    def scheme(self) -> AbstractScheme:
        """The configured scheme (``solver["scheme"]``) with its settings."""
        return make_scheme(self.solver)

    def run(self, **kwargs) -> Solution:
        """Simulate from t = 0 to ``t_end`` with step ``h`` in the configured
        ``dtype``, keeping every ``record_every``-th step
        (``SaveAt(every=record_every)``); keyword arguments go to
        :func:`~nsga_jax.simulate` (and take precedence)."""
        from .._first_step import check_run_fits
        from .._saveat import SaveAt
        from .._simulate import simulate

        kwargs = {"dtype": self.solver["dtype"], "saveat": SaveAt(every=self.solver["record_every"]), **kwargs}
        scheme = self.scheme()
        check_run_fits(self.model, scheme, kwargs, what=self.name, **self.run_length(kwargs["saveat"]))
        return simulate(
            self.model, scheme, 0.0, self.solver["t_end"], self.solver["h"],
            self.q0, self.v0, observables=self.observables, **kwargs,
        )

    def run_length(self, saveat: Any = None) -> dict[str, int]:
        """``n_steps`` and ``record_every`` of the run :meth:`run` makes
        (``saveat``: a :class:`~nsga_jax.SaveAt` given to it, else the
        configured ``record_every``), for the checks ahead of it."""
        from .._validation import time_grid

        n_steps = time_grid(0.0, self.solver["t_end"], self.solver["h"], self.solver["dtype"], t1_name="t_end")[3]
        every = getattr(saveat, "every", self.solver["record_every"])
        return {"n_steps": n_steps, "record_every": every if isinstance(every, int) else 1}


def make_scheme(solver: dict[str, Any]) -> AbstractScheme:
    """A scheme from validated solver settings (scheme, rho_inf, theta, tol_r, tol_f, max_iter, impact_law,
    impacts, newton_start, persistent_contacts)."""
    from .._integrators import scheme_class

    common = dict(tol_r=solver["tol_r"], tol_f=solver["tol_f"], max_iter=solver["max_iter"])
    name = solver["scheme"]
    cls: Any = scheme_class(name)  # its own setting: MJ's theta, the generalized-α schemes' rho_inf
    if name == "mj":
        return cls(theta=solver["theta"], **common)
    if solver.get("impact_law", "newton") != "newton":  # DS, DSn (check_solver refuses the others)
        common["impact_law"] = solver["impact_law"]
    if solver.get("impacts", "end") == "instants":  # DS, DSn likewise
        common["impact_instants"] = True
    if solver.get("newton_start", "zero") == "previous":  # DS, DSn likewise
        common["warm_start"] = True
    if solver.get("persistent_contacts", "jumps") == "smooth":  # DS, DSn likewise
        common["persistent_contacts"] = True
    return cls(rho_inf=solver["rho_inf"], **common)


Make = Callable[[dict[str, Any], dict[str, Any]], tuple["Model", Any, Any, Callable]]
"""``make(p, concrete) -> (model, q0, v0, observables)``: JAX-traceable in the
float parameters ``p`` (so gradients flow from them); structural decisions
(sizes, indices, sides) read the validated Python values ``concrete``."""


@dataclass(frozen=True)
class SceneSpec:
    """A built-in scene: its parameters, solver defaults, and how to build it.

    ``make`` builds the model, the initial state and the observables from the
    parameters (see :data:`Make`); ``check`` refuses inconsistent setups (an
    initial penetration...) with a :class:`ConfigError`; ``exact`` gives the
    exact solution of some observables where there is one.
    """

    name: str
    description: str
    parameters: dict[str, Param]
    solver_defaults: dict[str, Any]
    make: Make
    check: Callable[[dict[str, Any]], None] | None = None
    exact: Callable[[dict[str, Any]], Callable] | None = None
    observables: tuple[str, ...] = field(default=())
    error_observables: tuple[str, ...] = field(default=())
    """The observables the paper's convergence studies measure (eq. 52)."""
    units: dict[str, str] = field(default_factory=dict)
    """The SI unit of each observable (``"m"``, ``"m/s"``, ``"N"``, ``"J"``,
    ``"rad"``, ``"rad/s"``; ``""`` for a dimensionless one), for plot axes."""
    plotted: tuple[str, ...] = field(default=())
    """The observables a run's plot shows by default (empty: every scalar one)."""

    def build(self, parameters: dict[str, Any], solver: dict[str, Any]) -> Scene:
        """A :class:`Scene` from validated parameters and solver settings
        (:func:`configure` has run the scene's check)."""
        model, q0, v0, observables = self.make(parameters, parameters)
        exact = self.exact(parameters) if self.exact is not None else None
        return Scene(self.name, model, np.asarray(q0, float), np.asarray(v0, float), parameters, solver,
                     observables, exact)

    def solver_specs(self) -> dict[str, Param]:
        specs = dict(SOLVER_PARAMS)
        for key, value in self.solver_defaults.items():
            p = specs[key]
            specs[key] = dataclasses.replace(p, default=value)
        return specs

    def default_toml(self) -> str:
        """The scene's config file with every default, documented."""
        lines = [f"# {self.description}", f'scene = "{self.name}"', "", "[parameters]"]
        for section, specs in (("parameters", self.parameters), ("solver", self.solver_specs())):
            if section == "solver":
                lines += ["", "[solver]"]
            for key, p in specs.items():
                unit = f" [{p.unit}]" if p.unit else ""
                lines.append(f"# {p.doc}{unit}; allowed: {p.range_text()}")
                lines.append(f"{key} = {_toml_value(p.default)}")
        return "\n".join(lines) + "\n"


def _toml_value(v) -> str:
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    return repr(float(v))


REGISTRY: dict[str, SceneSpec] = {}


def register(spec: SceneSpec) -> SceneSpec:
    REGISTRY[spec.name] = spec
    return spec


