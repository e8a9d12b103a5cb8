"""A planar rigid block on a line, its two bottom corners in contact: the
model the ``incline`` and ``rocking_block`` scenes share."""

from __future__ import annotations

from typing import Any


def block_on_line(mass: Any, length: Any, height: Any, *, position: Any, angle: Any, velocity: Any, normal: Any,
                  mu: Any, gravity: Any, contact: str) -> tuple[Any, Any]:
    """A :class:`~nsga_jax.system.RigidBody2D` "block" of ``mass`` [kg] and
    sides ``length`` × ``height`` [m] (its own x and y), its centre at
    ``position`` (2,) [m] turned by ``angle`` [rad], moving at ``velocity``
    (2,) [m/s]; its bottom corners (-length/2, -height/2) and
    (length/2, -height/2) touch the line through the origin of unit
    ``normal`` (2,) (plane contact ``contact``, e = 0, friction ``mu`` or
    None); gravity (0, -``gravity``) [m/s²]. Returns the model and the
    corners (2, 2) in the body frame [m]."""
    import jax.numpy as jnp

    from .._system import Gravity, PlaneContact, RigidBody2D, System

    corners = jnp.stack([jnp.stack([-0.5 * length, -0.5 * height]), jnp.stack([0.5 * length, -0.5 * height])])
    system = System(dim=2)
    system.add_body("block", RigidBody2D(mass, mass * (length**2 + height**2) / 12.0, position=position, angle=angle,
                                         velocity=velocity))
    system.add_contact(contact, PlaneContact("block", normal=normal, origin=jnp.zeros(2), e=jnp.asarray(0.0),
                                             points=corners, mu=mu))
    system.add_force("gravity", Gravity(jnp.stack([jnp.zeros_like(gravity), -gravity])))
    return system.model(), corners
