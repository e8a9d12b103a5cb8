"""Systems assembled from parts: bodies, joints, contacts and forces.

See :mod:`nsga_jax._system.base` for the conventions (anchors, dimensions) and
docs/systems.md for every part, its coordinates, parameters and units.
"""

from .base import GROUND, AbstractBody, AbstractContact, AbstractForce, AbstractJoint, Ground
from .bodies import PointMass, RigidBody2D
from .builder import System, check_initial_state
from .contacts import PlaneContact, SphereContact
from .face_contact import FaceContact
from .flexible import Bar, Beam2D
from .forces import Gravity, PrescribedForce, SpringDamper, TorsionalSpring
from .joints import Distance, Pin, Slider, Weld
from .joints3d import Revolute, Weld3D
from .model import SystemModel
from .rigid3d import RigidBody3D
from .solid import HexSolid

__all__ = [
    "GROUND", "AbstractBody", "AbstractContact", "AbstractForce", "AbstractJoint", "Ground",
    "PointMass", "RigidBody2D", "Bar", "Beam2D", "HexSolid", "System", "check_initial_state", "PlaneContact",
    "SphereContact", "FaceContact",
    "Gravity", "PrescribedForce", "SpringDamper", "TorsionalSpring", "Distance", "Pin", "Slider", "Weld",
    "RigidBody3D", "Revolute", "Weld3D",
    "SystemModel",
]
