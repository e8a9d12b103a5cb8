"""Scenes: a model, its initial state, named observables and solver settings,
built from a validated config (a built-in name or a TOML file)."""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax.numpy as jnp
import numpy as np

from .._simulate import Solution, simulate
from ..integrators.base import AbstractScheme
from ..integrators.cs import CS
from ..integrators.ds import DS, DSn
from ..integrators.mj import MJ
from ..models.base import Model
from ..results import ConfigError
from .params import SOLVER_PARAMS, Param, check_all


@dataclass
class Scene:
    """A ready-to-run system.

    Attributes:
        name: scene name.
        model: the :class:`~nsga_jax.models.Model`.
        q0, v0: initial coordinates and velocities (n,).
        parameters: the validated scene parameters.
        solver: the validated solver settings (scheme, h, t_end, rho_inf, ...).
        observe: ``Solution -> {name: array (N+1,)}``, the scene's observables.
        exact: ``ts -> {name: array}``, the exact solution of some observables
            where the scene has one (else ``None``).
    """

    name: str
    model: Model
    q0: np.ndarray
    v0: np.ndarray
    parameters: dict[str, Any]
    solver: dict[str, Any]
    observe: Callable[[Solution], dict[str, np.ndarray]]
    exact: Callable[[np.ndarray], dict[str, np.ndarray]] | None = None

    @property
    def spec(self) -> "SceneSpec":
        return REGISTRY[self.name]

    def scheme(self) -> AbstractScheme:
        """The configured scheme (``solver["scheme"]``) with its settings."""
        return make_scheme(self.solver)

    def run(self, **kwargs) -> Solution:
        """Simulate from t = 0 to ``t_end`` with step ``h`` in the configured
        ``dtype``, keeping every ``record_every``-th step; keyword arguments go
        to :func:`~nsga_jax.simulate` (and take precedence)."""
        kwargs = {"dtype": self.solver["dtype"], "record_every": self.solver["record_every"], **kwargs}
        return simulate(
            self.model, self.scheme(), 0.0, self.solver["t_end"], self.solver["h"],
            self.q0, self.v0, observe=self.observe, **kwargs,
        )


def make_scheme(solver: dict[str, Any]) -> AbstractScheme:
    """A scheme from validated solver settings (scheme, rho_inf, theta, tol_r, tol_f, max_iter)."""
    common = dict(tol_r=solver["tol_r"], tol_f=solver["tol_f"], max_iter=solver["max_iter"])
    name = solver["scheme"]
    if name == "mj":
        return MJ(theta=solver["theta"], **common)
    cls = {"ds": DS, "dsn": DSn, "cs": CS}[name]
    return cls(rho_inf=solver["rho_inf"], **common)


Make = Callable[[dict[str, Any], dict[str, Any]], tuple[Model, Any, Any, Callable]]
"""``make(p, concrete) -> (model, q0, v0, observe)``: JAX-traceable in the
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
        """A :class:`Scene` from validated parameters and solver settings."""
        if self.check is not None:
            self.check(parameters)
        model, q0, v0, observe = self.make(parameters, parameters)
        exact = self.exact(parameters) if self.exact is not None else None
        return Scene(self.name, model, np.asarray(q0, float), np.asarray(v0, float), parameters, solver,
                     observe, exact)

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


def parse_override(text: str) -> tuple[str, Any]:
    """``"key=value"`` -> (key, typed value); the value is read as TOML, else kept as text."""
    if "=" not in text:
        raise ConfigError(f"--set expects key=value, got {text!r}")
    key, raw = (s.strip() for s in text.split("=", 1))
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key, value


def load_scene(name_or_path: str | Path, overrides: dict[str, Any] | None = None) -> Scene:
    """Build a scene from a built-in name or a TOML config, with overrides.

    Overrides are flat ``key: value`` pairs; a key is looked up among the
    scene's parameters, then the solver settings. Unknown keys, bad values and
    inconsistent setups (e.g. an initial penetration) raise
    :class:`~nsga_jax.ConfigError` before anything is compiled.
    """
    params_in: dict[str, Any] = {}
    solver_in: dict[str, Any] = {}
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise ConfigError(f"config file {str(path)!r} does not exist")
        try:
            data = tomllib.loads(path.read_text())
        except tomllib.TOMLDecodeError as err:
            raise ConfigError(f"{path}: invalid TOML: {err}") from None
        unknown = sorted(set(data) - {"scene", "parameters", "solver"})
        if unknown:
            raise ConfigError(f"{path}: unknown top-level key {unknown[0]!r}; allowed: scene, parameters, solver")
        if "scene" not in data:
            raise ConfigError(f"{path}: missing key 'scene' (one of {', '.join(sorted(REGISTRY))})")
        name = data["scene"]
        params_in.update(data.get("parameters", {}))
        solver_in.update(data.get("solver", {}))
    else:
        name = str(name_or_path)
    if name not in REGISTRY:
        raise ConfigError(f"unknown scene {name!r}; built-in scenes: {', '.join(sorted(REGISTRY))}")
    spec = REGISTRY[name]
    solver_specs = spec.solver_specs()
    for key, value in (overrides or {}).items():
        if key in spec.parameters:
            params_in[key] = value
        elif key in solver_specs:
            solver_in[key] = value
        else:
            allowed = ", ".join(sorted(spec.parameters) + sorted(solver_specs))
            raise ConfigError(f"unknown config key {key!r} for scene {name!r}; allowed keys: {allowed}")
    parameters = check_all(f"{name} parameter", spec.parameters, params_in)
    solver = check_all("solver", solver_specs, solver_in)
    if solver["h"] > solver["t_end"]:
        raise ConfigError(f"h must be in (0, t_end] = (0, {solver['t_end']}], got {solver['h']}")
    return spec.build(parameters, solver)


def parametrize(name_or_path: str | Path, overrides: dict[str, Any] | None = None,
                names: list[str] | tuple[str, ...] | None = None):
    """Differentiable parameters of a scene, separate from its static structure.

    Returns ``(params, build)``: ``params`` maps each chosen float parameter
    (default: all of them) to a float array, and ``build(params) -> (model, q0,
    v0, observe)`` is JAX-traceable in them, so one writes::

        params, build = parametrize("impacting_bar", names=["E", "e"])

        def loss(p):
            model, q0, v0, observe = build(p)
            traj = nsga_jax.trajectory(model, nsga_jax.DS(), 0.0, 1e-3, 1500, q0, v0)
            return jnp.mean(observe(traj)["tip_u"] ** 2)

        jax.grad(loss)(params)

    The scene is loaded and validated first (with ``overrides``); integer and
    choice parameters (element counts, mass-matrix kind) are structure, fixed
    at these values.
    """
    scene = load_scene(name_or_path, overrides)
    spec = scene.spec
    floats = [k for k, p in spec.parameters.items() if p.kind == "float"]
    names = list(floats if names is None else names)
    for k in names:
        if k not in floats:
            raise ConfigError(f"{k!r} is not a float parameter of {spec.name}; differentiable: {', '.join(floats)}")
    concrete = dict(scene.parameters)
    params = {k: jnp.asarray(concrete[k], dtype=float) for k in names}

    def build(p: dict[str, Any]):
        return spec.make({**concrete, **p}, concrete)

    return params, build
