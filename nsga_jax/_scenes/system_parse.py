"""A system file's tables parsed and validated into a
:class:`SystemDescription`, and the :class:`~nsga_jax.system.System` built
from it with given parameter values (see :mod:`nsga_jax._scenes.system_file`
for the format). Every error is a :class:`~nsga_jax.ConfigError` naming the
dotted path, the value and what is allowed."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from .._results import ConfigError
from .._system.catalog import CATALOG, STRUCTURE_KINDS, Field, fields
from .params import SOLVER_PARAMS, Param

TABLES = ("system", "bodies", "joints", "contacts", "forces", "solver")
"""The top-level tables of a system file."""
PART_KINDS = ("bodies", "joints", "contacts", "forces")
SYSTEM_KEYS = ("name", "description", "dim", "gravity")
"""The keys of ``[system]``."""
GROUND = "ground"

_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_SCENE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*\Z")


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
    """A parsed system file: the space dimension, whether ``[system]`` gives
    gravity, the parts, and the scene parameters with dotted paths."""

    dim: int
    gravity: bool
    parts: tuple[PartEntry, ...]
    parameters: dict[str, Param]


def _type_name(value: Any) -> str:
    return f"{type(value).__name__} {value!r}"


def numbers(path: str, value: Any, unit: str) -> np.ndarray:
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


def component_paths(path: str, shape: tuple[int, ...]) -> list[str]:
    return [".".join([path, *map(str, index)]) for index in np.ndindex(*shape)] if shape else [path]


def _float_params(path: str, array: np.ndarray, doc: str, field: Field) -> dict[str, Param]:
    rng = field.range
    out = {}
    indices = list(np.ndindex(*array.shape))
    for sub, x, index in zip(component_paths(path, array.shape), array.reshape(-1), indices):
        text = doc + "".join(f"[{i}]" for i in index)
        p = Param(float(x), text, field.unit, lo=rng.lo, hi=rng.hi, lo_open=rng.lo_open, hi_open=rng.hi_open)
        p.check(sub, float(x))
        out[sub] = p
    return out


def _structure(path: str, value: Any, kind: str) -> Any:
    ok = {"str": lambda v: isinstance(v, str),
          "int": lambda v: isinstance(v, int) and not isinstance(v, bool),
          "bool": lambda v: isinstance(v, bool),
          "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
          "ints": lambda v: isinstance(v, list) and all(isinstance(i, int) and not isinstance(i, bool) for i in v),
          "strs": lambda v: isinstance(v, list) and all(isinstance(s, str) for s in v),
          "nodes": lambda v: isinstance(v, str) or (isinstance(v, list) and all(
              isinstance(i, int) and not isinstance(i, bool) for i in v))}[kind]
    if not ok(value):
        raise ConfigError(f"{path} must be {STRUCTURE_KINDS[kind]}, got {_type_name(value)}")
    return tuple(value) if kind in ("ints", "strs", "nodes") and isinstance(value, list) else value


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
            array = numbers(sub, list(value) if isinstance(value, tuple) else value, f.unit)
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


def parse_system(path: Path, data: dict[str, Any]) -> tuple[str, str, SystemDescription, dict[str, Any]]:
    """``(name, description, parsed system, solver settings given)`` of a
    system file's tables (``path`` gives the default name, its stem)."""
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
        g = numbers("system.gravity", gravity, "m/s^2")
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
            if key == "nodes":
                continue  # node indices, or a face of the body (checked by the body)
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
    return jnp.stack([jnp.asarray(p[k], dtype=float) for k in component_paths(path, shape)]).reshape(shape)


def build_system(description: SystemDescription, p: dict[str, Any], concrete: dict[str, Any]):
    """The :class:`~nsga_jax.system.System` of a parsed file with the float
    parameters ``p`` (traceable) and the structural ones from ``concrete``;
    a part that refuses its values raises a :class:`ConfigError` naming it."""
    from .._system import Gravity, System

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


__all__ = ["GROUND", "PART_KINDS", "SYSTEM_KEYS", "TABLES", "PartEntry", "SystemDescription", "build_system",
           "component_paths", "numbers", "parse_system"]
