"""The elastic bar of the paper's §4.2: 1D linear finite elements against a wall."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from nsga_jax._assembly import ElementGroup, StaticIndex
from nsga_jax._custom_types import Matrix, Scalar, Vector
from nsga_jax._elements.bar import bar_consistent_mass, bar_internal_force, bar_lumped_mass
from nsga_jax._models.base import Model, count_rule
from nsga_jax._util import as_float
from nsga_jax._validation import POSITIVE, UNIT_INTERVAL


class ElasticBar(Model):
    """A uniform bar of ``n_elements`` two-node elements moving along its axis.

    Coordinates: nodal axial displacements u (n_elements + 1,) [m], positive
    toward the wall, node 0 at the free end and the last node (the tip) facing
    the wall. One unilateral constraint: the tip gap g = gap0 - u_tip >= 0.
    The model is linear (constant M and K), so the integrator factors its
    iteration matrices once.
    """

    E: Scalar = eqx.field(converter=as_float)
    rho: Scalar = eqx.field(converter=as_float)
    area: Scalar = eqx.field(converter=as_float)
    length: Scalar = eqx.field(converter=as_float)
    gap0: Scalar = eqx.field(converter=as_float)
    e: Scalar = eqx.field(converter=as_float)

    ranges = {"E": POSITIVE, "rho": POSITIVE, "area": POSITIVE, "length": POSITIVE, "e": UNIT_INTERVAL}

    def invalid(self) -> str | None:
        return count_rule("n_elements", self.n_elements)
    n_elements: int = eqx.field(static=True)
    lumped: bool = eqx.field(static=True, default=False)

    n_unilateral = 1
    constant_mass = True
    linear_force = True
    velocity_dependent_force = False
    linear_constraints = True

    @property
    def n_dof(self) -> int:
        return self.n_elements + 1

    @property
    def bandwidth(self) -> int:
        return 1  # two-node elements on consecutive dofs: M and K are tridiagonal

    @property
    def mbar(self) -> Scalar:
        return self.rho * self.area * self.length

    @property
    def elements(self) -> ElementGroup:
        ne = self.n_elements
        dofs = StaticIndex(np.stack([np.arange(ne), np.arange(1, ne + 1)], axis=1))
        params = tuple(jnp.broadcast_to(p, (ne,)) for p in (self.E * self.area, self.length / ne, self.rho * self.area))
        return ElementGroup(dofs=dofs, params=params)

    @property
    def _element_mass(self):
        return bar_lumped_mass if self.lumped else bar_consistent_mass

    def mass(self, q: Vector) -> Matrix:
        return self.elements.matrix(self._element_mass, self.n_dof)

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        return self.elements.matrix_product(self._element_mass, x)

    def force(self, q: Vector, v: Vector, t: Scalar) -> Vector:
        return self.elements.forces(bar_internal_force, q, v, self.n_dof)

    def tangents(self, q: Vector, v: Vector, t: Scalar) -> tuple[Matrix, Matrix]:
        return self.elements.tangents(bar_internal_force, q, v, self.n_dof, velocity_dependent=False)

    def unilateral(self, q: Vector) -> jax.Array:
        return (self.gap0 - q[-1])[None]

    @property
    def restitution(self) -> jax.Array:
        return self.e[None]

    def energy(self, q: Vector, v: Vector) -> Scalar:
        """Kinetic + strain energy [J]."""
        M = self.mass(q)
        K, _ = self.tangents(q, v, jnp.zeros(()))
        return 0.5 * v @ M @ v + 0.5 * q @ K @ q
