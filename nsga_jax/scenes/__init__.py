"""Built-in scenes and config loading."""

from . import bouncing_ball, impacting_bar, rigid_pendulum  # noqa: F401  (registration)
from .base import REGISTRY, Scene, SceneSpec, load_scene, parse_override
from .params import SOLVER_PARAMS, Param

__all__ = ["REGISTRY", "Scene", "SceneSpec", "load_scene", "parse_override", "Param", "SOLVER_PARAMS"]
