"""Hand-written models: the references the system-built scenes are tested against.

Each implements :class:`nsga_jax.Model` by hand, as a user's own model would
(docs/own-model.md), for the scenes that ``nsga_jax.System`` builds from parts:
the equality tests (tests/test_system_rigid.py, tests/test_system_flexible.py)
compare the two function by function and run by run, and the other tests use
them as small models written against the bare interface.
"""

from .bar import ElasticBar
from .beam2d import PlanarBeam
from .point_mass import BouncingBall, RigidPendulum
from .rigid_body import RigidBody
from .solid import HexSolid

__all__ = ["BouncingBall", "ElasticBar", "HexSolid", "PlanarBeam", "RigidBody", "RigidPendulum"]
