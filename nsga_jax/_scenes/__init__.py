"""Built-in scenes and config loading.

- :mod:`.spec`: :class:`Scene`, :class:`SceneSpec` and the registry;
- :mod:`.files`: ``--set`` overrides, TOML files and Python scene files;
- :mod:`.loading`: from a name or a path to a validated scene;
- :mod:`.system_file`: TOML system files (parts and joints) as scenes;
- one module per built-in scene, which registers it on import.
"""

from . import (  # noqa: F401  (registration)
    bouncing_ball,
    box_stack,
    double_pendulum,
    flexible_appendage,
    flexible_cube,
    flexible_pendulum,
    impacting_bar,
    incline,
    newtons_cradle,
    rigid_box,
    rigid_pendulum,
    rocking_block,
    slider_crank,
)
from .files import load_scene_file, parse_override, read_toml
from .loading import Configured, configure, load_scene, parametrize, resolve_scene
from .params import SOLVER_PARAMS, Param
from .spec import REGISTRY, Scene, SceneSpec, make_scheme, register

__all__ = ["REGISTRY", "Scene", "SceneSpec", "Configured", "configure", "load_scene", "load_scene_file", "make_scheme",
           "parametrize", "parse_override", "read_toml", "register", "resolve_scene", "Param", "SOLVER_PARAMS"]
