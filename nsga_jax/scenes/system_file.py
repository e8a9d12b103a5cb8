"""System files: a scene described as data (TOML), its parts from the catalog.

::

    [system]
    name = "ball_between_walls"      # default: the file's stem
    description = "A ball bouncing between two walls"
    dim = 2                          # default: the length of gravity
    gravity = [0.0, -9.81]           # m/s^2; default: none

    [bodies.ball]
    type = "point_mass"
    mass = 1.0
    position = [0.0, 1.0]
    velocity = [2.0, 0.0]

    [contacts.floor]
    type = "plane"
    body = "ball"
    normal = [0.0, 1.0]
    origin = [0.0, 0.0]
    e = 0.9

    [solver]
    h = 1e-3
    t_end = 2.0

Every table of ``bodies``, ``joints``, ``contacts`` and ``forces`` names a
part: ``type`` (a name of :data:`nsga_jax.system.catalog.CATALOG`) and the
class's constructor arguments (:func:`nsga_jax.system.catalog.fields`).
Every number becomes a scene parameter with a dotted path
(``bodies.ball.mass``, ``bodies.ball.velocity.0`` for a vector's component,
``contacts.wall.points.1.0`` for a matrix's entry, ``system.gravity.1``), a
float :class:`~nsga_jax.scenes.params.Param` with the class's range, so
``--set``, ``--grid``, ``--params`` and :func:`~nsga_jax.scenes.parametrize`
reach it; integers and flags (``n_elements``, ``lumped``, node indices) are
structural parameters; body names and node lists are fixed by the file.

:func:`load_system_file` validates a file (every error a
:class:`~nsga_jax.ConfigError` naming the dotted path, the value and what is
allowed) and registers its :class:`~nsga_jax.scenes.SceneSpec`.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from ..results import ConfigError
from ..system.base import AbstractBody
from ..system.catalog import CATALOG, STRUCTURE_KINDS, Field, fields
from .base import REGISTRY, SceneSpec, register
from .params import SOLVER_PARAMS, Param

TABLES = ("system", "bodies", "joints", "contacts", "forces", "solver")
"""The top-level tables of a system file."""
PART_KINDS = ("bodies", "joints", "contacts", "forces")
SYSTEM_KEYS = ("name", "description", "dim", "gravity")
"""The keys of ``[system]``."""
GROUND = "ground"

_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_SCENE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*\Z")


def is_system_file(path: str | Path) -> bool:
    """Whether ``path`` is a TOML system file (no ``scene`` key, a
    ``[bodies]`` or ``[system]`` table) rather than a config."""
    path = Path(path)
    if path.suffix != ".toml" or not path.is_file():
        return False
    data = _read_toml(path)
    return "scene" not in data and ("bodies" in data or "system" in data)


def _stamp(path: Path) -> tuple[int, int]:
    st = path.stat()
    return st.st_mtime_ns, st.st_size


_TOML: dict[Path, tuple[tuple[int, int], dict[str, Any]]] = {}


def _read_toml(path: Path) -> dict[str, Any]:
    """The file's TOML tables (read again only when the file changed)."""
    path = path.expanduser().resolve()
    try:
        stamp = _stamp(path)
        if path in _TOML and _TOML[path][0] == stamp:
            return _TOML[path][1]
        data = tomllib.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as err:
        raise ConfigError(f"{path}: not a UTF-8 text file ({err.reason} at byte {err.start})") from None
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: invalid TOML: {err}") from None
    except OSError as err:
        raise ConfigError(f"{path}: cannot be read ({err.strerror})") from None
    _TOML[path] = (stamp, data)
    return data


# ------------------------------------------------------------------ parsing


@dataclass(frozen=True)
class PartEntry:
    """One part of a system file: its kind, name and class, its fixed
    structure (body names, node lists), its float fields' shapes and its
    structural parameters (integers, flags), each addressed by a dotted path."""

    kind: str
    name: str
    cls: type
    fixed: dict[str, Any]
    arrays: dict[str, tuple[int, ...]]
    structure: tuple[str, ...]

    @property
    def path(self) -> str:
        return f"{self.kind}.{self.name}"


@dataclass(frozen=True)
class SystemDescription:
    """A parsed system file: the space dimension, gravity's shape (or None),
    the parts, and the scene parameters with dotted paths."""

    dim: int
    gravity: bool
    parts: tuple[PartEntry, ...]
    parameters: dict[str, Param]


def _type_name(value: Any) -> str:
    return f"{type(value).__name__} {value!r}"


def _numbers(path: str, value: Any, unit: str) -> np.ndarray:
    """A number or a rectangular nested list of numbers as a float array."""
    label = f"{path} [{unit}]" if unit else path

    def walk(x, where):
        if isinstance(x, list):
            return [walk(y, f"{where}.{i}") for i, y in enumerate(x)]
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise ConfigError(f"{where} must be a number, got {_type_name(x)}"
                              + ("" if where != path else f" ({label} is a number or a list of numbers)"))
        return float(x)

    nested = walk(value, path)
    try:
        array = np.asarray(nested, dtype=float)
    except ValueError:
        raise ConfigError(f"{label} must be a number or a rectangular list of numbers (each row the same "
                          f"length), got {value!r}") from None
    return array


def _component_paths(path: str, shape: tuple[int, ...]) -> list[str]:
    return [".".join([path, *map(str, index)]) for index in np.ndindex(*shape)] if shape else [path]


def _float_params(path: str, array: np.ndarray, doc: str, field: Field) -> dict[str, Param]:
    rng = field.range
    out = {}
    for sub, x in zip(_component_paths(path, array.shape), array.reshape(-1)):
        p = Param(float(x), doc, field.unit, lo=rng.lo, hi=rng.hi, lo_open=rng.lo_open, hi_open=rng.hi_open)
        p.check(sub, float(x))
        out[sub] = p
    return out


def _structure(path: str, value: Any, kind: str) -> Any:
    ok = {"str": lambda v: isinstance(v, str),
          "int": lambda v: isinstance(v, int) and not isinstance(v, bool),
          "bool": lambda v: isinstance(v, bool),
          "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
          "ints": lambda v: isinstance(v, list) and all(isinstance(i, int) and not isinstance(i, bool) for i in v),
          "strs": lambda v: isinstance(v, list) and all(isinstance(s, str) for s in v)}[kind]
    if not ok(value):
        raise ConfigError(f"{path} must be {STRUCTURE_KINDS[kind]}, got {_type_name(value)}")
    return tuple(value) if kind in ("ints", "strs") else value


def _signature_text(type_name: str, specs: dict[str, Field]) -> str:
    return f"{type_name}(" + ", ".join(f.name if f.required else f"{f.name}=..." for f in specs.values()) + ")"


def _parse_part(kind: str, name: str, table: Any) -> tuple[PartEntry, dict[str, Param]]:
    path = f"{kind}.{name}"
    if not _IDENTIFIER.match(name):
        raise ConfigError(f"{path}: a part's name must be an identifier (letters, digits, _), got {name!r}")
    if name == GROUND:
        raise ConfigError(f"{path}: 'ground' is the fixed frame's name; choose another")
    if not isinstance(table, dict):
        raise ConfigError(f"{path} must be a table ([{path}] with type = ... and the part's fields), "
                          f"got {_type_name(table)}")
    types = CATALOG[kind]
    if "type" not in table:
        raise ConfigError(f"{path}: missing key 'type'; allowed types: {', '.join(types)}")
    type_name = table["type"]
    if not isinstance(type_name, str) or type_name not in types:
        raise ConfigError(f"{path}.type: unknown {kind[:-1] if kind != 'bodies' else 'body'} type "
                          f"{type_name!r}; allowed: {', '.join(types)}")
    cls = types[type_name]
    specs = fields(cls)
    unknown = [k for k in table if k != "type" and k not in specs]
    if unknown:
        raise ConfigError(f"{path}: unknown key {unknown[0]!r} for type {type_name!r}; allowed: type, "
                          f"{', '.join(specs)}")
    missing = [f.name for f in specs.values() if f.required and f.name not in table]
    if missing:
        raise ConfigError(f"{path}: missing required key {missing[0]!r} ({_signature_text(type_name, specs)})")
    fixed: dict[str, Any] = {}
    arrays: dict[str, tuple[int, ...]] = {}
    structure: list[str] = []
    params: dict[str, Param] = {}
    for f in specs.values():
        sub = f"{path}.{f.name}"
        doc = f"{name}: {type_name} {f.name}"
        if f.kind == "float":
            value = table.get(f.name, f.default)
            if value is None:
                continue
            array = _numbers(sub, list(value) if isinstance(value, tuple) else value, f.unit)
            if array.size == 0:
                fixed[f.name] = array.tolist()
                continue
            arrays[f.name] = array.shape
            params.update(_float_params(sub, array, doc, f))
        elif f.name in table:
            value = _structure(sub, table[f.name], f.kind)
            if f.kind == "int":
                params[sub] = Param(value, doc, kind="int")
                structure.append(f.name)
            elif f.kind == "bool":
                flags = cast(tuple[str, ...], (False, True))  # a flag's two choices (the scenes' are strings)
                params[sub] = Param(value, doc, kind="choice", choices=flags)
                structure.append(f.name)
            else:
                fixed[f.name] = value
    return PartEntry(kind, name, cls, fixed, arrays, tuple(structure)), params


def _parse_system(path: Path, data: dict[str, Any]) -> tuple[str, str, SystemDescription, dict[str, Any]]:
    unknown = [k for k in data if k not in TABLES]
    if unknown:
        raise ConfigError(f"unknown top-level table {unknown[0]!r}; allowed: {', '.join(TABLES)}"
                          + (" (a config names its scene with scene = ...; a system file has no scene key)"
                             if unknown[0] in ("scene", "parameters") else ""))
    for table in TABLES:
        if table in data and not isinstance(data[table], dict):
            raise ConfigError(f"[{table}] must be a table, got {_type_name(data[table])}")
    system = data.get("system", {})
    extra = [k for k in system if k not in SYSTEM_KEYS]
    if extra:
        raise ConfigError(f"system: unknown key {extra[0]!r}; allowed: {', '.join(SYSTEM_KEYS)}")
    name = system.get("name", path.stem)
    if not isinstance(name, str) or not _SCENE_NAME.match(name):
        raise ConfigError(f"system.name must be a scene name (letters, digits, _ . -), got {name!r}"
                          + (" (the file's stem; set [system] name = ...)" if "name" not in system else ""))
    description = system.get("description", f"System file {path.name}")
    if not isinstance(description, str):
        raise ConfigError(f"system.description must be a string, got {_type_name(description)}")
    parameters: dict[str, Param] = {}
    gravity = system.get("gravity")
    if gravity is not None:
        g = _numbers("system.gravity", gravity, "m/s^2")
        if g.ndim != 1 or g.shape[0] not in (1, 2, 3):
            raise ConfigError(f"system.gravity [m/s^2] must be a vector of 1, 2 or 3 numbers, got {gravity!r}")
        parameters.update(_float_params("system.gravity", g, "gravitational acceleration",
                                        Field("gravity", "float", False, None, "m/s^2")))
    if "dim" in system:
        dim = system["dim"]
        if isinstance(dim, bool) or dim not in (1, 2, 3):
            raise ConfigError(f"system.dim must be 1, 2 or 3 (the space dimension), got {dim!r}")
    elif gravity is not None:
        dim = len(gravity)
    else:
        raise ConfigError("system.dim: missing (the space dimension, 1, 2 or 3; or give system.gravity)")
    if gravity is not None and len(gravity) != dim:
        raise ConfigError(f"system.gravity [m/s^2] must have {dim} coordinates (system.dim), got {gravity!r}")
    if not data.get("bodies"):
        raise ConfigError("bodies: a system needs at least one body ([bodies.NAME] with type = ...; types: "
                          f"{', '.join(CATALOG['bodies'])})")
    parts = []
    for kind in PART_KINDS:
        for part_name, table in data.get(kind, {}).items():
            entry, params = _parse_part(kind, part_name, table)
            parts.append(entry)
            parameters.update(params)
    if gravity is not None and "gravity" in data.get("forces", {}):
        raise ConfigError("forces.gravity: the name is taken by system.gravity; choose another")
    bodies = [p.name for p in parts if p.kind == "bodies"]
    for p in parts:
        if p.kind == "bodies":
            continue
        for key, value in p.fixed.items():
            refs = (value,) if isinstance(value, str) else value if isinstance(value, tuple) else ()
            for ref in refs:
                if isinstance(ref, str) and ref != GROUND and ref not in bodies:
                    raise ConfigError(f"{p.path}.{key} = {ref!r} names a body that does not exist; bodies: "
                                      f"{', '.join(bodies)} (and ground)")
    given = {}
    for key, value in data.get("solver", {}).items():
        if key not in SOLVER_PARAMS:
            raise ConfigError(f"solver: unknown key {key!r}; allowed: {', '.join(SOLVER_PARAMS)}")
        given[key] = SOLVER_PARAMS[key].check(f"solver.{key}", value)
    return name, description, SystemDescription(dim, gravity is not None, tuple(parts), parameters), given


# ----------------------------------------------------------------- building


def _assemble(p: dict[str, Any], path: str, shape: tuple[int, ...]):
    import jax.numpy as jnp

    if not shape:
        return jnp.asarray(p[path], dtype=float)
    return jnp.stack([jnp.asarray(p[k], dtype=float) for k in _component_paths(path, shape)]).reshape(shape)


def build_system(description: SystemDescription, p: dict[str, Any], concrete: dict[str, Any]):
    """The :class:`~nsga_jax.system.System` of a parsed file with the float
    parameters ``p`` (traceable) and the structural ones from ``concrete``;
    a part that refuses its values raises a :class:`ConfigError` naming it."""
    from ..system import Gravity, System

    system = System(description.dim)
    if description.gravity:
        system.add_force("gravity", Gravity(_assemble(p, "system.gravity", (description.dim,))))
    for entry in description.parts:
        kwargs = dict(entry.fixed)
        kwargs.update({k: _assemble(p, f"{entry.path}.{k}", shape) for k, shape in entry.arrays.items()})
        kwargs.update({k: concrete[f"{entry.path}.{k}"] for k in entry.structure})
        try:
            part = entry.cls(**kwargs)
        except ConfigError as err:
            raise ConfigError(f"{entry.path}: {err}") from None
        except (ValueError, TypeError, IndexError) as err:  # a shape the class cannot take
            raise ConfigError(f"{entry.path}: {entry.cls.__name__} cannot take these values: {err}") from None
        system.add(entry.kind, entry.name, part)
    return system


def _model(system):
    try:
        return system.model()
    except ConfigError as err:
        raise ConfigError(str(err).removeprefix("SystemModel.")) from None


def _has_angle(cls: type) -> bool:
    return getattr(cls, "angle", None) is not AbstractBody.angle


def observable_units(description: SystemDescription) -> dict[str, str]:
    """The scene's observables and their units: per body the position of its
    reference point (a rigid body's origin, a flexible body's tip node
    ``tip_x``...) and its velocity, its angle and angular velocity where it
    has one; per contact its smallest gap and its force; per joint its
    violation; ``energy`` where every force is conservative."""
    axes = "xyz"[:description.dim]
    out: dict[str, str] = {}
    for entry in description.parts:
        if entry.kind == "bodies":
            prefix = f"{entry.name}.tip_" if getattr(entry.cls, "has_nodes", False) else f"{entry.name}."
            out.update({f"{prefix}{a}": "m" for a in axes})
            if _has_angle(entry.cls):
                out[f"{prefix}theta"] = "rad"
            out.update({f"{prefix}v{a}": "m/s" for a in axes})
            if _has_angle(entry.cls):
                out[f"{prefix}omega"] = "rad/s"
    for entry in description.parts:
        if entry.kind == "contacts":
            out[f"{entry.name}.gap"], out[f"{entry.name}.force"] = "m", "N"
    for entry in description.parts:
        if entry.kind == "joints":
            out[f"{entry.name}.violation"] = "m"
    if all(getattr(e.cls, "conservative", True) for e in description.parts if e.kind == "forces"):
        out["energy"] = "J"
    return out


def observables_of(model, names: tuple[str, ...]) -> Callable:
    """``Solution -> {name: (rows,)}`` of :func:`observable_units`' names on ``model``."""
    import jax
    import jax.numpy as jnp

    from ..system.base import point

    def observables(sol):
        q, v = sol.q, sol.v
        out = {}
        for body_name, body in zip(model.body_names, model.bodies):
            cut = model.coordinates(body_name)
            node = -1 if body.has_nodes else None
            prefix = f"{body_name}.tip_" if body.has_nodes else f"{body_name}."

            def place(qb, body=body, node=node):
                x = point(body, qb, jnp.zeros((0,), qb.dtype), node)
                return (jnp.concatenate([x, body.angle(qb, node)[None]]) if body.has_angle else x)

            x, xdot = jax.vmap(lambda qb, vb, place=place: jax.jvp(place, (qb,), (vb,)))(q[:, cut], v[:, cut])
            labels = list("xyz"[:body.dim]) + (["theta"] if body.has_angle else [])
            rates = [f"v{a}" for a in "xyz"[:body.dim]] + (["omega"] if body.has_angle else [])
            for i, (label, rate) in enumerate(zip(labels, rates)):
                out[prefix + label], out[prefix + rate] = x[:, i], xdot[:, i]
        if model.contact_names:
            gaps = jax.vmap(model.unilateral)(q)
            nb = model.n_bilateral
            for name in model.contact_names:
                rows = model.rows("contacts", name)
                out[f"{name}.gap"] = jnp.min(gaps[:, rows.start - nb:rows.stop - nb], axis=1)
                out[f"{name}.force"] = jnp.sum(sol.impulse[:, rows], axis=1) / sol.h
        if model.joint_names:
            g = jax.vmap(model.bilateral)(q)
            for name in model.joint_names:
                out[f"{name}.violation"] = jnp.max(jnp.abs(g[:, model.rows("joints", name)]), axis=1)
        if "energy" in names:
            out["energy"] = jax.vmap(model.energy)(q, v)
        return {k: out[k] for k in names}

    return observables


def _residuals(model, q0, v0):
    import jax.numpy as jnp

    g = model.constraints(q0)
    nb = model.n_bilateral
    w = model.constraint_jacobian(q0)[:nb] @ v0
    zero = jnp.zeros((1,), q0.dtype)
    return (jnp.max(jnp.abs(jnp.concatenate([g[:nb], zero]))), jnp.max(jnp.abs(jnp.concatenate([w, zero]))),
            jnp.min(jnp.concatenate([g[nb:], zero])))


_RESIDUALS: Callable | None = None


def _initial_state_holds(model, q0, v0, tolerance: float = 1e-9) -> bool:
    """Whether the initial state passes :func:`~nsga_jax.system.check_initial_state`'s
    tests, from one compiled evaluation (compiled once per system structure:
    a sweep validates each member in about a millisecond); where it does not,
    that function names the culprit."""
    global _RESIDUALS
    import equinox as eqx
    import jax.numpy as jnp

    if _RESIDUALS is None:
        _RESIDUALS = eqx.filter_jit(_residuals)
    q0, v0 = jnp.asarray(q0, float), jnp.asarray(v0, float)
    g, w, gap = (float(x) for x in _RESIDUALS(model, q0, v0))
    scale = max(1.0, float(jnp.abs(q0).max(initial=0.0)))
    vscale = max(1.0, float(jnp.abs(v0).max(initial=0.0)))
    return g <= tolerance * scale and w <= tolerance * vscale and gap >= -tolerance * scale


def spec_from_file(path: str | Path) -> SceneSpec:
    """The :class:`~nsga_jax.scenes.SceneSpec` of a system file, validated
    (every error a :class:`ConfigError` starting with the file's path)."""
    path = Path(path).expanduser()
    data = _read_toml(path)
    try:
        name, description, parsed, solver = _parse_system(path, data)
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from None
    units = observable_units(parsed)
    names = tuple(units)

    def make(p, concrete):
        model = _model(build_system(parsed, p, concrete))
        q0, v0 = model.initial_state()
        return model, q0, v0, observables_of(model, names)

    def check(parameters):
        from ..system import check_initial_state

        try:
            model, q0, v0, _ = make(parameters, parameters)
            if not _initial_state_holds(model, q0, v0):
                check_initial_state(model, q0, v0)  # names the joint or contact
        except ConfigError as err:
            raise ConfigError(f"{path}: {err}") from None

    positions = tuple(k for k, u in units.items() if u in ("m", "rad") and not k.endswith((".gap", ".violation")))
    gaps = tuple(k for k in units if k.endswith(".gap"))
    energy = ("energy",) if "energy" in units else ()
    plotted = (gaps[:3] + energy)
    plotted = positions[:9 - len(plotted)] + plotted  # at most 9 panels
    return SceneSpec(name=name, description=description, parameters=parsed.parameters, solver_defaults=solver,
                     make=make, check=check, observables=names, error_observables=positions, units=units,
                     plotted=plotted)


_FILES: dict[Path, tuple[tuple[int, int], SceneSpec]] = {}
_FILE_NAMES: set[str] = set()
"""The scene names system files registered (which a later system file may take over)."""


def load_system_file(path: str | Path) -> str:
    """Validate a system file, register its scene and return the scene's name.

    The file is read again only when it changed; the scene is registered
    again at every call (the last file loaded under a name is the one that
    name runs). A name that a built-in or Python scene holds is refused.
    """
    path = Path(path).expanduser()
    if not path.is_file():
        raise ConfigError(f"system file {str(path)!r} does not exist")
    key = path.resolve()
    stamp = _stamp(key)
    if key not in _FILES or _FILES[key][0] != stamp:
        _FILES[key] = (stamp, spec_from_file(path))
    spec = _FILES[key][1]
    held = REGISTRY.get(spec.name)
    if held is not None and held is not spec and spec.name not in _FILE_NAMES:
        raise ConfigError(f"{path}: the scene name {spec.name!r} is a built-in scene's; set [system] name = ... "
                          "to another name")
    _FILE_NAMES.add(spec.name)
    register(spec)
    return spec.name


def flatten(table: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested TOML tables as dotted keys: ``{"bodies": {"ball": {"mass": 1}}}``
    -> ``{"bodies.ball.mass": 1}`` (a config's dotted ``[parameters]`` keys)."""
    out: dict[str, Any] = {}
    for key, value in table.items():
        full = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(flatten(value, full + "."))
        else:
            out[full] = value
    return out


def expand_components(values: dict[str, Any], parameters: dict[str, Any]) -> dict[str, Any]:
    """A whole vector or matrix given for a path whose components are the
    parameters (``bodies.ball.velocity = [1.0, 0.0]``) as those components
    (``bodies.ball.velocity.0``, ``.1``); other keys unchanged."""
    out: dict[str, Any] = {}
    for key, value in values.items():
        if not isinstance(value, list) or key in parameters or f"{key}.0" not in parameters:
            out[key] = value
            continue
        array = _numbers(key, value, "")
        paths = _component_paths(key, array.shape)
        expected = sorted(k for k in parameters if k.startswith(f"{key}.") and k[len(key) + 1:][:1].isdigit())
        if sorted(paths) != expected:
            raise ConfigError(f"{key} has the components {', '.join(expected)}; got {value!r} (shape {array.shape})")
        out.update(zip(paths, array.reshape(-1).tolist()))
    return out


__all__ = ["PART_KINDS", "SYSTEM_KEYS", "TABLES", "PartEntry", "SystemDescription", "build_system",
           "expand_components", "flatten",
           "is_system_file", "load_system_file", "observable_units", "observables_of", "spec_from_file"]
