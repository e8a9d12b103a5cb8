"""A planar geometrically exact beam: a chain of Reissner elements with a pivot
at its root and a wall facing its tip."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from nsga_jax._assembly import ElementGroup, StaticIndex
from nsga_jax._custom_types import Matrix, Scalar, Vector
from nsga_jax._elements.beam2d import beam_energy, beam_internal_force, beam_mass
from nsga_jax._models.base import Model, count_rule
from nsga_jax._util import as_float
from nsga_jax._validation import POSITIVE, UNIT_INTERVAL, Range

from .rules import side_rule


class PlanarBeam(Model):
    """A straight beam of ``n_elements`` Reissner elements in the (x, y) plane.

    Coordinates: per node (x, y, θ), node-major, node 0 at the root. In the
    reference configuration the beam leaves the root at ``root`` along the
    direction ``angle`` (rad from the x-axis). Gravity acts along -y.

    Constraints, chosen by static flags: ``pinned`` adds two linear bilateral
    constraints fixing the root node's x and y (rotation free); ``clamped``
    also fixes its rotation; ``wall`` adds one unilateral constraint
    ``side (x_tip - wall_x) >= 0``.

    Attributes (leaves): EA, GAs, EI [N, N, N m²]; length [m]; rhoA [kg/m];
    rhoI [kg m]; gravity [m/s²]; root (2,) [m]; angle [rad]; wall_x [m];
    side (±1); e (restitution); tip_load (3,) constant external force on the
    tip node [N, N, N m].
    """

    EA: Scalar = eqx.field(converter=as_float)
    GAs: Scalar = eqx.field(converter=as_float)
    EI: Scalar = eqx.field(converter=as_float)
    length: Scalar = eqx.field(converter=as_float)
    rhoA: Scalar = eqx.field(converter=as_float)
    rhoI: Scalar = eqx.field(converter=as_float)
    gravity: Scalar = eqx.field(converter=as_float)
    root: jax.Array = eqx.field(converter=as_float)
    angle: Scalar = eqx.field(converter=as_float)
    wall_x: Scalar = eqx.field(converter=as_float)
    side: Scalar = eqx.field(converter=as_float)
    e: Scalar = eqx.field(converter=as_float)
    tip_load: jax.Array = eqx.field(converter=as_float)

    ranges = {"EA": POSITIVE, "GAs": POSITIVE, "EI": POSITIVE, "length": POSITIVE, "rhoA": POSITIVE,
              "rhoI": Range(0.0), "e": UNIT_INTERVAL}

    def invalid(self) -> str | None:
        return count_rule("n_elements", self.n_elements) or side_rule(self.side)
    n_elements: int = eqx.field(static=True)
    pinned: bool = eqx.field(static=True, default=True)
    clamped: bool = eqx.field(static=True, default=False)
    wall: bool = eqx.field(static=True, default=True)
    lumped: bool = eqx.field(static=True, default=False)

    constant_mass = True
    velocity_dependent_force = False
    linear_constraints = True

    @property
    def n_dof(self) -> int:
        return 3 * (self.n_elements + 1)

    @property
    def n_bilateral(self) -> int:
        return 3 if self.clamped else (2 if self.pinned else 0)

    @property
    def n_unilateral(self) -> int:
        return 1 if self.wall else 0

    @property
    def mbar(self) -> Scalar:
        return self.rhoA * self.length

    @property
    def elements(self) -> ElementGroup:
        ne = self.n_elements
        dofs = StaticIndex(np.arange(3 * ne)[:, None].reshape(ne, 3)[:, :1] + np.arange(6)[None, :])
        params = tuple(jnp.broadcast_to(p, (ne,)) for p in (self.EA, self.GAs, self.EI, self.length / ne,
                                                            self.rhoA, self.rhoI, self.angle))
        return ElementGroup(dofs=dofs, params=params)

    def reference(self) -> Vector:
        """Reference (straight, unstressed) coordinates (n,)."""
        s = jnp.linspace(0.0, 1.0, self.n_elements + 1) * self.length
        x = self.root[0] + s * jnp.cos(self.angle)
        y = self.root[1] + s * jnp.sin(self.angle)
        return jnp.stack([x, y, jnp.full_like(s, self.angle)], axis=1).reshape(-1)

    def mass(self, q: Vector) -> Matrix:
        return self.elements.matrix(lambda p: beam_mass(p, self.lumped), self.n_dof)

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        return self.elements.matrix_product(lambda p: beam_mass(p, self.lumped), x)

    def external_force(self) -> Vector:
        """Gravity (consistent, ρA g per unit length on x and y nodes) and the tip load."""
        ne = self.n_elements
        le = self.length / ne
        weights = jnp.full((ne + 1,), le).at[0].set(le / 2).at[-1].set(le / 2)
        f = jnp.zeros((ne + 1, 3), weights.dtype).at[:, 1].set(-self.rhoA * self.gravity * weights)
        return (f.at[-1].add(self.tip_load)).reshape(-1)

    def force(self, q: Vector, v: Vector, t: Scalar) -> Vector:
        return self.elements.forces(beam_internal_force, q, v, self.n_dof) + self.external_force()

    def tangents(self, q: Vector, v: Vector, t: Scalar) -> tuple[Matrix, Matrix]:
        return self.elements.tangents(beam_internal_force, q, v, self.n_dof, velocity_dependent=False)

    def bilateral(self, q: Vector) -> jax.Array:
        if self.clamped:
            return q[:3] - jnp.concatenate([self.root, self.angle[None]])
        if self.pinned:
            return q[:2] - self.root
        return jnp.zeros((0,), q.dtype)

    def unilateral(self, q: Vector) -> jax.Array:
        if not self.wall:
            return jnp.zeros((0,), q.dtype)
        return (self.side * (q[-3] - self.wall_x))[None]

    @property
    def restitution(self) -> jax.Array:
        return self.e[None] if self.wall else jnp.zeros((0,))

    def angular_speed(self, q: Vector, v: Vector) -> float:
        """The largest cross-section angular speed |θ̇| [rad/s] over the nodes."""
        return float(jnp.max(jnp.abs(v[2::3])))

    def strain_energy(self, q: Vector) -> Scalar:
        return jnp.sum(jax.vmap(beam_energy)(self.elements.gather(q), self.elements.params))

    def energy(self, q: Vector, v: Vector) -> Scalar:
        """Kinetic + strain + gravitational (minus tip-load work) energy [J]."""
        return 0.5 * v @ self.mass_product(q, v) + self.strain_energy(q) - self.external_force() @ q
