"""Built-in scenes and config loading."""

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
from .base import REGISTRY, Scene, SceneSpec, configure, load_scene, parametrize, parse_override, register
from .params import SOLVER_PARAMS, Param

__all__ = ["REGISTRY", "Scene", "SceneSpec", "configure", "load_scene", "parametrize", "parse_override", "register",
           "Param", "SOLVER_PARAMS"]
