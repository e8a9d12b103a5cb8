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
part: ``type`` (a name of :data:`nsga_jax._system.catalog.CATALOG`) and the
class's constructor arguments (:func:`nsga_jax._system.catalog.fields`).
Every number becomes a scene parameter with a dotted path
(``bodies.ball.mass``, ``bodies.ball.velocity.0`` for a vector's component,
``contacts.wall.points.1.0`` for a matrix's entry, ``system.gravity.1``), a
float :class:`~nsga_jax._scenes.params.Param` with the class's range, so
``--set``, ``--grid``, ``--params`` and :func:`~nsga_jax.scenes.parametrize`
reach it; integers and flags (``n_elements``, ``lumped``, node indices) are
structural parameters; body names and node lists are fixed by the file.

:func:`load_system_file` validates a file (every error a
:class:`~nsga_jax.ConfigError` naming the dotted path, the value and what is
allowed) and registers its :class:`~nsga_jax.scenes.SceneSpec`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .._results import ConfigError
from .files import read_toml
from .spec import REGISTRY, SceneSpec, register
from .system_observables import observable_units, observables_of
from .system_parse import build_system, component_paths, numbers, parse_system


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
    except OSError as err:
        raise ConfigError(f"{path}: cannot be read ({err.strerror})") from None
    if path in _TOML and _TOML[path][0] == stamp:
        return _TOML[path][1]
    data = read_toml(path)
    _TOML[path] = (stamp, data)
    return data


def _model(system):
    try:
        return system.model()
    except ConfigError as err:
        raise ConfigError(str(err).removeprefix("SystemModel.")) from None


def spec_from_file(path: str | Path) -> SceneSpec:
    """The :class:`~nsga_jax.scenes.SceneSpec` of a system file, validated
    (every error a :class:`ConfigError` starting with the file's path)."""
    path = Path(path).expanduser()
    data = _read_toml(path)
    try:
        name, description, parsed, solver = parse_system(path, data)
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from None
    units = observable_units(parsed)
    names = tuple(units)

    def make(p, concrete):
        model = _model(build_system(parsed, p, concrete))
        q0, v0 = model.initial_state()
        return model, q0, v0, observables_of(model, names)

    def check(parameters):
        from .._system import check_initial_state

        try:
            model, q0, v0, _ = make(parameters, parameters)
            check_initial_state(model, q0, v0)  # names the joint or contact
        except ConfigError as err:
            raise ConfigError(f"{path}: {err}") from None

    positions = tuple(k for k, u in units.items() if u in ("m", "rad") and not k.endswith((".gap", ".violation")))
    gaps = tuple(k for k in units if k.endswith(".gap"))
    energy = ("energy",) if "energy" in units else ()
    slips = tuple(k for k in units if k.endswith(".slip"))
    plotted = (gaps[:3] + slips[:2] + energy)
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
        array = numbers(key, value, "")
        paths = component_paths(key, array.shape)
        expected = sorted(k for k in parameters if k.startswith(f"{key}.") and k[len(key) + 1:][:1].isdigit())
        if sorted(paths) != expected:
            raise ConfigError(f"{key} has the components {', '.join(expected)}; got {value!r} (shape {array.shape})")
        out.update(zip(paths, array.reshape(-1).tolist()))
    return out


__all__ = ["expand_components", "flatten", "is_system_file", "load_system_file", "spec_from_file"]
