"""A 3D solid of trilinear hexahedra (St Venant–Kirchhoff), falling on a floor."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from nsga_jax._assembly import ElementGroup, StaticIndex
from nsga_jax._custom_types import Matrix, Scalar, Vector
from nsga_jax._elements.hex8 import hex8_body_force, hex8_geometry, hex8_internal_force, hex8_mass, lame, svk_energy
from nsga_jax._models import Model
from nsga_jax._util import as_float
from nsga_jax._validation import POSITIVE, UNIT_INTERVAL, Range


class HexSolid(Model):
    """A mesh of hex8 elements; coordinates are the current nodal positions
    (n = 3 × nodes, node-major), gravity along -z, and node–plane contacts
    ``z_node - floor_z >= 0`` at the ``contact_nodes``.

    Attributes:
        reference_nodes: reference positions (N, 3) [m].
        connectivity: element-to-node map (E, 8), static.
        contact_nodes: node indices in contact with the floor (static).
        E, nu, rho: Young's modulus [Pa], Poisson's ratio, density [kg/m³].
        gravity [m/s²], floor_z [m], e: restitution (shared by every contact).
        shape_gradients: dN/dX at each element's Gauss points (E, 8, 8, 3) [1/m], and
            volumes: their integration weights (E, 8) [m³]; both derived from
            ``reference_nodes`` at construction (build a new model to change
            the mesh), so that no force evaluation recomputes the geometry.
    """

    reference_nodes: jax.Array
    E: Scalar
    nu: Scalar
    rho: Scalar
    gravity: Scalar
    floor_z: Scalar
    e: Scalar

    ranges = {"E": POSITIVE, "nu": Range(-1.0, 0.5, lo_open=True, hi_open=True), "rho": POSITIVE,
              "e": UNIT_INTERVAL}
    def invalid(self) -> str | None:
        nodes = self.reference_nodes.shape[-2] if self.reference_nodes.ndim == 2 else 0
        conn, contact = self.connectivity.array, self.contact_nodes.array
        if self.reference_nodes.ndim != 2 or self.reference_nodes.shape[-1] != 3 or nodes == 0:
            return f"reference_nodes must have shape (N, 3) with N >= 1, got {tuple(self.reference_nodes.shape)}"
        if conn.ndim != 2 or conn.shape[1] != 8 or conn.shape[0] == 0:
            return f"connectivity must have shape (E, 8) with E >= 1, got {conn.shape}"
        for name, idx in (("connectivity", conn), ("contact_nodes", contact)):
            if idx.size and (idx.min() < 0 or idx.max() >= nodes):
                return f"{name} must index nodes in [0, {nodes - 1}], got indices in [{idx.min()}, {idx.max()}]"
        if np.any(np.asarray(self.volumes) <= 0):
            return "every element must have a positive volume (check the node order of the connectivity)"
        return None

    connectivity: StaticIndex = eqx.field(static=True)
    contact_nodes: StaticIndex = eqx.field(static=True)
    shape_gradients: jax.Array
    volumes: jax.Array

    constant_mass = True
    velocity_dependent_force = False
    linear_constraints = True

    def __init__(self, reference_nodes, E, nu, rho, gravity, floor_z, e, connectivity: StaticIndex,
                 contact_nodes: StaticIndex):
        self.reference_nodes = as_float(reference_nodes)
        self.E, self.nu, self.rho = as_float(E), as_float(nu), as_float(rho)
        self.gravity, self.floor_z, self.e = as_float(gravity), as_float(floor_z), as_float(e)
        self.connectivity, self.contact_nodes = connectivity, contact_nodes
        self.shape_gradients, self.volumes = jax.vmap(hex8_geometry)(self.reference_nodes[connectivity.array])

    @property
    def n_nodes(self) -> int:
        return self.reference_nodes.shape[-2]

    @property
    def n_dof(self) -> int:
        return 3 * self.n_nodes

    @property
    def n_unilateral(self) -> int:
        return self.contact_nodes.shape[0]

    @property
    def elements(self) -> ElementGroup:
        conn = self.connectivity.array
        dofs = StaticIndex((3 * conn[:, :, None] + np.arange(3)[None, None, :]).reshape(len(conn), 24))
        lam, mu = lame(self.E, self.nu)
        ne = len(conn)
        params = (self.shape_gradients, self.volumes, *(jnp.broadcast_to(p, (ne,)) for p in (lam, mu, self.rho)))
        return ElementGroup(dofs=dofs, params=params)

    @property
    def mbar(self) -> Scalar:
        """Total mass ρ V [kg]."""
        return self.rho * jnp.sum(self.volumes)

    def reference(self) -> Vector:
        return self.reference_nodes.reshape(-1)

    def mass(self, q: Vector) -> Matrix:
        return self.elements.matrix(hex8_mass, self.n_dof)

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        return self.elements.matrix_product(hex8_mass, x)

    def external_force(self) -> Vector:
        g = jnp.array([0.0, 0.0, -1.0], self.gravity.dtype) * self.gravity
        group = self.elements
        fe = jax.vmap(lambda p: hex8_body_force(p, g))(group.params)
        return jnp.zeros((self.n_dof,), fe.dtype).at[group.dofs.array].add(fe)

    def force(self, q: Vector, v: Vector, t: Scalar) -> Vector:
        return self.elements.forces(hex8_internal_force, q, v, self.n_dof) + self.external_force()

    def tangents(self, q: Vector, v: Vector, t: Scalar) -> tuple[Matrix, Matrix]:
        return self.elements.tangents(hex8_internal_force, q, v, self.n_dof, velocity_dependent=False)

    def unilateral(self, q: Vector) -> jax.Array:
        return q.reshape(-1, 3)[self.contact_nodes.array, 2] - self.floor_z

    @property
    def restitution(self) -> jax.Array:
        return jnp.full((self.n_unilateral,), self.e)

    def strain_energy(self, q: Vector) -> Scalar:
        group = self.elements
        return jnp.sum(jax.vmap(svk_energy)(group.gather(q), group.params))

    def energy(self, q: Vector, v: Vector) -> Scalar:
        """Kinetic + strain + gravitational energy [J]."""
        return 0.5 * v @ self.mass_product(q, v) + self.strain_energy(q) - self.external_force() @ q
