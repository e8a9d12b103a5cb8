"""The part catalog: the ``type`` names of a system file and their part classes.

A part's fields are its class's constructor arguments
(:func:`inspect.signature`), each described by a :class:`Field`: a float
field (a number, a vector or a matrix: differentiable parameters, the
class's own field a pytree leaf) or a structural one (an integer, a flag, a
body name, a list of node indices: a static field). Adding a part type is
one line in :data:`CATALOG`.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
from dataclasses import dataclass
from typing import Any

from .._validation import Range
from .base import AbstractPart
from .bodies import PointMass, RigidBody2D
from .contacts import PlaneContact, SphereContact
from .face_contact import FaceContact
from .flexible import Bar, Beam2D
from .forces import Gravity, PrescribedForce, SpringDamper, TorsionalSpring
from .joints import Distance, Pin, Slider, Weld
from .joints3d import Revolute, Weld3D
from .rigid3d import RigidBody3D
from .solid import HexSolid

CATALOG: dict[str, dict[str, type[AbstractPart]]] = {
    "bodies": {"point_mass": PointMass, "rigid_body_2d": RigidBody2D, "rigid_body_3d": RigidBody3D,
               "bar": Bar, "beam_2d": Beam2D, "hex_solid": HexSolid},
    "joints": {"pin": Pin, "distance": Distance, "weld": Weld, "slider": Slider, "revolute": Revolute,
               "weld_3d": Weld3D},
    "contacts": {"plane": PlaneContact, "sphere": SphereContact, "face": FaceContact},
    "forces": {"gravity": Gravity, "spring_damper": SpringDamper, "torsional_spring": TorsionalSpring,
               "prescribed": PrescribedForce},
}
"""``{kind: {type name: part class}}`` for the four kinds of parts (the tables of a system file)."""

UNITS: dict[str, str] = {
    "mass": "kg", "inertia": "kg m^2", "position": "m", "velocity": "m/s", "angle": "rad",
    "angular_velocity": "rad/s", "E": "Pa", "rho": "kg/m^3", "area": "m^2", "second_moment": "m^4",
    "length": "m", "at": "m", "at_a": "m", "at_b": "m", "scale": "m", "origin": "m", "points": "m", "radius": "m",
    "radius_a": "m", "radius_b": "m", "acceleration": "m/s^2", "stiffness": "N/m", "rest_length": "m",
    "damping": "N s/m", "rest_angle": "rad", "direction": "N", "frequency": "Hz", "phase": "rad", "size": "m",
    "axis": "", "axis_b": "", "rotation": "", "half_extent": "m", "margin": "m", "depth": "m",
}
"""The SI unit of a float field, by argument name (``""``: dimensionless or not listed)."""

CLASS_UNITS: dict[type, dict[str, str]] = {
    TorsionalSpring: {"stiffness": "N m/rad", "damping": "N m s/rad"},
}
"""Units that differ from :data:`UNITS` for one class."""

STRUCTURE_KINDS = {"str": "a string", "int": "an integer", "bool": "true or false", "ints": "a list of integers",
                   "strs": "a list of strings", "number": "a number",
                   "nodes": "a list of node indices or a face name (a solid's \"bottom\", \"top\", ...)"}
"""What each kind of structural field holds, for error messages."""


@dataclass(frozen=True)
class Field:
    """One constructor argument of a part class.

    Attributes:
        name: the argument's name (the key in a system file).
        kind: ``"float"`` (a number or a nested list of numbers: parameters),
            or a structural kind of :data:`STRUCTURE_KINDS`.
        required: whether the argument has no default.
        default: its default (``None`` where required).
        unit: the SI unit of a float field.
        range: the allowed interval of a float field's values (the class's ``ranges``).
    """

    name: str
    kind: str
    required: bool
    default: Any
    unit: str = ""
    range: Range = Range()


def _structure_kind(annotation: str) -> str | None:
    """The structural kind of a static field's type annotation; ``None`` for
    one a file cannot give (a Python function)."""
    text = annotation.replace(" ", "")
    if "Callable" in text:
        return None
    if text.startswith("tuple[str"):
        return "strs"
    if text.startswith("tuple[int"):
        return "ints"
    for kind in ("str", "bool", "int"):
        if text.split("|")[0] == kind:
            return kind
    return "number"


@functools.cache
def fields(cls: type[AbstractPart]) -> dict[str, Field]:
    """The fields of a part class, by constructor argument, in signature order.

    An argument is matched to the class's dataclass field of the same name
    (or ``name_``, ``name0``, as the bodies store ``mass_`` and
    ``position0``): a static field is structure, any other is floats.
    """
    declared = {f.name: f for f in dataclasses.fields(cls)}
    units = {**UNITS, **CLASS_UNITS.get(cls, {})}
    out = {}
    for arg in inspect.signature(cls).parameters.values():
        if arg.kind in (arg.VAR_POSITIONAL, arg.VAR_KEYWORD):
            continue
        field = next((declared[n] for n in (arg.name, arg.name + "_", arg.name + "0") if n in declared), None)
        required = arg.default is inspect.Parameter.empty
        default = None if required else arg.default
        if field is not None and field.metadata.get("static", False):
            kind = "nodes" if arg.name == "nodes" else _structure_kind(str(field.type))
            if kind is None:
                continue
            out[arg.name] = Field(arg.name, kind, required, default)
        else:
            rng = cls.ranges.get(field.name, Range()) if field is not None else Range()
            out[arg.name] = Field(arg.name, "float", required, default, units.get(arg.name, ""), rng)
    return out


def part_class(kind: str, type_name: str) -> type[AbstractPart]:
    """The class of ``type_name`` among ``kind``'s parts; :class:`KeyError` if unknown."""
    return CATALOG[kind][type_name]


__all__ = ["CATALOG", "CLASS_UNITS", "Field", "STRUCTURE_KINDS", "UNITS", "fields", "part_class"]
