"""Scenes: a model, its initial state, named observables and solver settings,
built from a validated config (a built-in name or a TOML file)."""

from __future__ import annotations

import dataclasses
import importlib.util
import sys
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..packaged import locate
from ..results import ConfigError
from .params import SOLVER_PARAMS, Param, check_all, check_solver

if TYPE_CHECKING:  # the numerical modules load (with JAX) only when a scene is built or run
    from ..integrators.base import AbstractScheme
    from ..models.base import Model
    from ..solution import Solution


@dataclass
class Scene:
    """A ready-to-run system.

    Attributes:
        name: scene name.
        model: the :class:`~nsga_jax.models.Model`.
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
        from .._simulate import simulate
        from ..first_step import check_run_fits
        from ..saveat import SaveAt

        kwargs = {"dtype": self.solver["dtype"], "saveat": SaveAt(every=self.solver["record_every"]), **kwargs}
        scheme = self.scheme()
        check_run_fits(self.model, scheme, kwargs, what=self.name)
        return simulate(
            self.model, scheme, 0.0, self.solver["t_end"], self.solver["h"],
            self.q0, self.v0, observables=self.observables, **kwargs,
        )


def make_scheme(solver: dict[str, Any]) -> AbstractScheme:
    """A scheme from validated solver settings (scheme, rho_inf, theta, tol_r, tol_f, max_iter, impact_law)."""
    from ..integrators import scheme_class

    common = dict(tol_r=solver["tol_r"], tol_f=solver["tol_f"], max_iter=solver["max_iter"])
    name = solver["scheme"]
    cls: Any = scheme_class(name)  # its own setting: MJ's theta, the generalized-α schemes' rho_inf
    if name == "mj":
        return cls(theta=solver["theta"], **common)
    if solver.get("impact_law", "newton") != "newton":  # DS, DSn (check_solver refuses the others)
        common["impact_law"] = solver["impact_law"]
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


SCENE_FILE_SUFFIXES = (".toml", ".py")


def read_toml(path: Path) -> dict[str, Any]:
    """A TOML file's tables; a file that is not UTF-8, not TOML or not
    readable is a :class:`ConfigError` naming the path and why."""
    try:
        return tomllib.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as err:
        raise ConfigError(f"{path}: not a UTF-8 text file ({err.reason} at byte {err.start})") from None
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: invalid TOML: {err}") from None
    except OSError as err:
        raise ConfigError(f"{path}: cannot be read ({err.strerror})") from None


def _read_config(path: Path) -> dict[str, Any]:
    """A TOML config's tables, checked for shape: ``scene`` a string,
    ``parameters`` and ``solver`` tables, nothing else."""
    if not path.is_file():
        what = "is a folder" if path.is_dir() else "does not exist"
        raise ConfigError(f"config file {str(path)!r} {what}")
    data = read_toml(path)
    unknown = sorted(set(data) - {"scene", "parameters", "solver"})
    if unknown:
        raise ConfigError(f"{path}: unknown top-level key {unknown[0]!r}; allowed: scene, parameters, solver")
    if "scene" not in data:
        raise ConfigError(f"{path}: missing key 'scene' (one of {', '.join(sorted(REGISTRY))}, or a scene file); "
                          "a system file has [bodies.NAME] tables")
    if not isinstance(data["scene"], str):
        raise ConfigError(f"{path}: 'scene' must be a string (a scene name or a .py scene file), "
                          f"got {type(data['scene']).__name__} {data['scene']!r}")
    for table in ("parameters", "solver"):
        if not isinstance(data.get(table, {}), dict):
            raise ConfigError(f"{path}: [{table}] must be a table of key = value pairs, "
                              f"got {type(data[table]).__name__} {data[table]!r}")
    return data


_SCENE_FILES: dict[Path, tuple[str, ...]] = {}


def load_scene_file(path: str | Path) -> tuple[str, ...]:
    """Import a Python file that registers scenes (``register(SceneSpec(...))``)
    and return the names it registered. A file is imported once per process;
    later calls return the same names."""
    path = Path(path).expanduser()
    if not path.is_file():
        raise ConfigError(f"scene file {str(path)!r} does not exist")
    path = path.resolve()
    if path not in _SCENE_FILES:
        before = dict(REGISTRY)
        name = f"nsga_jax_scene_file_{len(_SCENE_FILES)}_{path.stem}"
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None:
            raise ConfigError(f"scene file {str(path)!r} cannot be imported as Python")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)  # errors in the user's file keep their traceback
        added = tuple(k for k, v in REGISTRY.items() if before.get(k) is not v)
        if not added:
            raise ConfigError(f"scene file {str(path)!r} registers no scene; call "
                              "nsga_jax.scenes.register(SceneSpec(...)) in it")
        _SCENE_FILES[path] = added
    return _SCENE_FILES[path]


def resolve_scene(name_or_path: str | Path, relative_to: Path | None = None) -> tuple[str, Path | None]:
    """``(scene name, config path or None)`` for a built-in name, a ``.toml``
    config, a ``.toml`` system file (:mod:`nsga_jax.scenes.system_file`,
    registered under its name), a ``.py`` scene file, or ``file.py:name``
    (one of several scenes a file registers). A built-in name is a name even where a file or folder
    of that name exists; a relative ``configs/...`` or ``examples/...`` path that does not exist is
    read from the package (:func:`nsga_jax.packaged.locate`)."""
    text = str(name_or_path)
    if text in REGISTRY and not text.endswith(SCENE_FILE_SUFFIXES):
        return text, None
    file, _, chosen = text.partition(".py:")
    if chosen or text.endswith(".py"):
        path = locate(file + ".py" if chosen else text, relative_to)
        names = load_scene_file(path)
        if chosen:
            if chosen not in names:
                raise ConfigError(f"scene file {str(path)!r} registers {', '.join(names)}, not {chosen!r}")
            return chosen, None
        if len(names) > 1:
            raise ConfigError(f"scene file {str(path)!r} registers several scenes ({', '.join(names)}); "
                              f"choose one as {path}:NAME")
        return names[0], None
    if text.endswith(".toml"):
        from .system_file import is_system_file, load_system_file

        path = locate(text, relative_to)
        if not path.is_file():
            where = f" (a config's scene is read relative to the config's folder, {str(relative_to)!r})" \
                if relative_to is not None else ""
            raise ConfigError(f"scene or config file {str(path)!r} does not exist{where}")
        if is_system_file(path):
            return load_system_file(path), None
        return "", path
    hint = " (a file or folder of that name exists, but only .toml configs and .py scene files are read)" \
        if Path(text).exists() else ""
    raise ConfigError(f"unknown scene {text!r}{hint}; built-in scenes: {', '.join(sorted(REGISTRY))}; "
                      "or give a .toml config or a .py scene file")


@dataclass(frozen=True)
class Configured:
    """A scene's validated settings, before its model is built (no JAX)."""

    spec: SceneSpec
    parameters: dict[str, Any]
    solver: dict[str, Any]

    def build(self) -> Scene:
        return self.spec.build(self.parameters, self.solver)


def configure(name_or_path: str | Path, overrides: dict[str, Any] | None = None) -> Configured:
    """Validate a scene's settings (a built-in name, a TOML config or a Python
    scene file, see :func:`resolve_scene`, with overrides) without building
    its model: every field against its range, the solver's cross-field rules
    and the scene's own consistency check (an initial penetration...).
    Raises :class:`~nsga_jax.ConfigError` (or :class:`TypeError`)."""
    if not isinstance(name_or_path, (str, Path)):
        raise TypeError(f"scene must be a scene name or a path (str or pathlib.Path), "
                        f"got {type(name_or_path).__name__} {name_or_path!r}")
    if overrides is not None and not isinstance(overrides, dict):
        raise TypeError(f"overrides must be a dict of key: value, got {type(overrides).__name__}")
    params_in: dict[str, Any] = {}
    solver_in: dict[str, Any] = {}
    name, path = resolve_scene(name_or_path)
    if path is not None:
        from .system_file import flatten  # dotted [parameters] keys of a system file's config

        data = _read_config(path)
        name, inner = resolve_scene(data["scene"], relative_to=path.parent)
        if inner is not None:
            raise ConfigError(f"{path}: scene = {data['scene']!r} is a config, not a scene; name a scene, a .py "
                              "scene file or a system file")
        params_in.update(flatten(data.get("parameters", {})))
        solver_in.update(data.get("solver", {}))
    spec = REGISTRY[name]
    solver_specs = spec.solver_specs()
    from .system_file import expand_components

    params_in = expand_components(params_in, spec.parameters)
    for key, value in expand_components(overrides or {}, spec.parameters).items():
        if key in spec.parameters:
            params_in[key] = value
        elif key in solver_specs:
            solver_in[key] = value
        else:
            allowed = ", ".join(sorted(spec.parameters) + sorted(solver_specs))
            raise ConfigError(f"unknown config key {key!r} for scene {name!r}; allowed keys: {allowed}")
    parameters = check_all(f"{name} parameter", spec.parameters, params_in)
    solver = check_all("solver", solver_specs, solver_in)
    check_solver(solver)
    if spec.check is not None:
        spec.check(parameters)
    return Configured(spec, parameters, solver)


def load_scene(name_or_path: str | Path, overrides: dict[str, Any] | None = None) -> Scene:
    """Build a scene from a built-in name, a TOML config or a Python scene
    file (see :func:`resolve_scene`), with overrides.

    Overrides are flat ``key: value`` pairs; a key is looked up among the
    scene's parameters, then the solver settings. Unknown keys, bad values and
    inconsistent setups (e.g. an initial penetration) raise
    :class:`~nsga_jax.ConfigError` before anything is compiled
    (:func:`configure`).
    """
    return configure(name_or_path, overrides).build()


def parametrize(name_or_path: str | Path, overrides: dict[str, Any] | None = None,
                names: list[str] | tuple[str, ...] | None = None):
    """Differentiable parameters of a scene, separate from its static structure.

    Returns ``(params, build)``: ``params`` maps each chosen float parameter
    (default: all of them) to a float array, and ``build(params) -> (model, q0,
    v0, observables)`` is JAX-traceable in them, so one writes::

        params, build = parametrize("impacting_bar", names=["E", "e"])

        def loss(p):
            model, q0, v0, observables = build(p)
            sol = nsga_jax.integrate(model, nsga_jax.DS(), 0.0, 1.5, 1e-3, q0, v0)
            return jnp.mean(observables(sol)["tip_u"] ** 2)

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
    import jax.numpy as jnp

    params = {k: jnp.asarray(concrete[k], dtype=float) for k in names}

    def build(p: dict[str, Any]):
        return spec.make({**concrete, **p}, concrete)

    return params, build
