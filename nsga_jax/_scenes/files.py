"""Reading what a user names on the command line or in a config: ``--set``
overrides, TOML files and Python scene files (which register scenes when
imported). Every unreadable or ill-shaped file is a
:class:`~nsga_jax.ConfigError` naming the path and why."""

from __future__ import annotations

import importlib.util
import sys
import tomllib
from pathlib import Path
from typing import Any

from .._results import ConfigError
from .spec import REGISTRY


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


def read_config(path: Path) -> dict[str, Any]:
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


