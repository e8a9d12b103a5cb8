"""The parts a system is built from, and the system itself (public namespace).

Bodies, joints, contacts and forces, and :class:`System`, which compiles them
into one model (:class:`SystemModel`). The parts' coordinates, parameters and
units are in docs/systems.md; the implementation lives in the private
``nsga_jax._system`` package.
"""

from ._system import (
    GROUND,
    AbstractBody,
    AbstractContact,
    AbstractForce,
    AbstractJoint,
    Bar,
    Beam2D,
    Distance,
    FaceContact,
    Gravity,
    Ground,
    HexSolid,
    Pin,
    PlaneContact,
    PointMass,
    PrescribedForce,
    Revolute,
    RigidBody2D,
    RigidBody3D,
    Slider,
    SphereContact,
    SpringDamper,
    System,
    SystemModel,
    TorsionalSpring,
    Weld,
    Weld3D,
    check_initial_state,
)

__all__ = [
    "GROUND", "AbstractBody", "AbstractContact", "AbstractForce", "AbstractJoint", "Ground",
    "PointMass", "RigidBody2D", "Bar", "Beam2D", "HexSolid", "System", "check_initial_state", "PlaneContact",
    "SphereContact", "FaceContact",
    "Gravity", "PrescribedForce", "SpringDamper", "TorsionalSpring", "Distance", "Pin", "Slider", "Weld",
    "RigidBody3D", "Revolute", "Weld3D",
    "SystemModel",
]
