"""Scenes: the built-in ones by name, and writing one's own (public namespace).

:func:`load_scene` builds a registered scene (``"bouncing_ball"``, ...) or a
scene file; :func:`parametrize` gives a scene's parameters as a function for
sweeps and gradients; a new scene is a :class:`SceneSpec` of :class:`Param` s
(with ranges such as :data:`POSITIVE`, :data:`UNIT_INTERVAL` or a
:class:`Range`) passed to :func:`register`. docs/own-model.md shows the whole
path; the implementation lives in the private ``nsga_jax._scenes`` package.
"""

from ._scenes import (
    REGISTRY,
    SOLVER_PARAMS,
    Configured,
    Param,
    Scene,
    SceneSpec,
    configure,
    load_scene,
    load_scene_file,
    make_scheme,
    parametrize,
    parse_override,
    read_toml,
    register,
    resolve_scene,
)
from ._validation import POSITIVE, UNIT_INTERVAL, Range

__all__ = ["REGISTRY", "Scene", "SceneSpec", "Configured", "configure", "load_scene", "load_scene_file", "make_scheme",
           "parametrize", "parse_override", "read_toml", "register", "resolve_scene", "Param", "SOLVER_PARAMS",
           "POSITIVE", "UNIT_INTERVAL", "Range"]
