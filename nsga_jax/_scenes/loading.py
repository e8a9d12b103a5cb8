"""From a name or a path to a validated scene: :func:`resolve_scene` finds
the scene (built-in, config, system file or Python scene file),
:func:`configure` validates its settings without JAX, :func:`load_scene`
builds it, :func:`parametrize` separates its differentiable parameters."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .._packaged import locate
from .._results import ConfigError
from .files import SCENE_FILE_SUFFIXES, load_scene_file, read_config
from .params import check_all, check_solver
from .spec import REGISTRY, Scene, SceneSpec


def resolve_scene(name_or_path: str | Path, relative_to: Path | None = None) -> tuple[str, Path | None]:
    """``(scene name, config path or None)`` for a built-in name, a ``.toml``
    config, a ``.toml`` system file (:mod:`nsga_jax._scenes.system_file`,
    registered under its name), a ``.py`` scene file, or ``file.py:name``
    (one of several scenes a file registers). A built-in name is a name even where a file or folder
    of that name exists; a relative ``configs/...`` or ``examples/...`` path that does not exist is
    read from the package (:func:`nsga_jax._packaged.locate`)."""
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
        from .system_file import is_system_file, load_system_file  # (with JAX: only for a .toml)

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

        data = read_config(path)
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
    at these values. A float64 scene (the default ``dtype``) with JAX's
    64-bit mode off is refused by name: its parameters would be float32.
    """
    scene = load_scene(name_or_path, overrides)
    from .._precision import require_x64_for

    require_x64_for(scene.solver["dtype"])  # its parameters would be float32 arrays without a word
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
