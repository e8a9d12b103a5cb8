"""Models: the abstract :class:`Model` and the built-in systems."""

from .bar import ElasticBar
from .base import Model
from .point_mass import BouncingBall, RigidPendulum

__all__ = ["Model", "BouncingBall", "RigidPendulum", "ElasticBar"]
