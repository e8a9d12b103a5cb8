"""A 3D flexible body of a system: a box-shaped St Venant–Kirchhoff solid of
hex8 elements (:mod:`nsga_jax._elements.hex8`), assembled element by element.

Its material points are nodes, named by index or, for contacts, by face.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._assembly import ElementGroup, StaticIndex
from .._blocks import ElementMatrix, KroneckerMass
from .._compat import dot_sum
from .._custom_types import Matrix, Scalar, Vector
from .._elements.hex8 import (
    hex8_body_force,
    hex8_geometry,
    hex8_internal_force,
    hex8_mass,
    hex8_mass_blocks,
    hex8_stiffness_blocks,
    lame,
    structured_hex_mesh,
    svk_energy,
)
from .._models.base import count_rule
from .._results import ConfigError
from .._util import as_float
from .._validation import POSITIVE, Range
from .base import AbstractBody
from .flexible import node_index

FACES = {"left": (0, 0), "right": (0, -1), "front": (1, 0), "back": (1, -1), "bottom": (2, 0), "top": (2, -1)}
"""A box's faces: (axis, grid index along it): left/right x-min/x-max,
front/back y-min/y-max, bottom/top z-min/z-max."""


class HexSolid(AbstractBody):
    """A box-shaped 3D St Venant–Kirchhoff solid meshed with ``divisions``
    (nx, ny, nz) trilinear hexahedra (:mod:`nsga_jax._elements.hex8`),
    initially unstressed.

    Coordinates: the current nodal positions (3 N,) [m], node-major; node
    (i, j, k) of the grid (``i`` along x, 0 ... nx) is number
    ``i + (nx + 1) (j + (ny + 1) k)`` (:meth:`node`). Its faces are node sets
    named ``left``/``right`` (x-min/x-max), ``front``/``back`` (y),
    ``bottom``/``top`` (z) (:meth:`node_set`), which a
    :class:`~nsga_jax.system.PlaneContact` names as ``nodes="bottom"``.

    The reference nodes, the shape-function gradients dN/dX (E, 8, 8, 3)
    [1/m] and the Gauss weights (E, 8) [m³] are computed from ``size`` and
    ``position`` at construction (build a new body to change the box), so
    that no force evaluation recomputes the geometry.

    Attributes:
        size: the box's sides (3,) [m] (a number: a cube).
        position: the box's centre (3,) [m]; velocity: initial velocity (3,) [m/s].
        E [Pa], nu (Poisson's ratio), rho [kg/m³].
        divisions: (nx, ny, nz) elements along x, y, z (static).
    """

    size: Vector
    position0: Vector
    velocity0: Vector
    E: Scalar
    nu: Scalar
    rho: Scalar
    reference_nodes: Matrix
    shape_gradients: jax.Array
    volumes: Matrix
    divisions: tuple[int, int, int] = eqx.field(static=True)
    connectivity: StaticIndex = eqx.field(static=True)

    ranges = {"size": POSITIVE, "E": POSITIVE, "nu": Range(-1.0, 0.5, lo_open=True, hi_open=True), "rho": POSITIVE}
    linear_force = False
    has_nodes = True
    dim = 3  # type: ignore[assignment]

    def __init__(self, size, divisions, E, nu, rho, position=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.0)):
        if np.ndim(divisions) == 0:
            divisions = (divisions,) * 3
        if len(divisions) != 3:
            raise ConfigError(f"HexSolid.divisions must be 3 element counts (x, y, z), got {divisions!r}")
        for d in divisions:
            rule = count_rule("divisions", d)
            if rule:
                raise ConfigError(f"HexSolid.{rule}")
        self.divisions = (int(divisions[0]), int(divisions[1]), int(divisions[2]))
        self.size = jnp.broadcast_to(as_float(size), (3,))
        self.position0, self.velocity0 = as_float(position), as_float(velocity)
        self.E, self.nu, self.rho = as_float(E), as_float(nu), as_float(rho)
        unit, conn = structured_hex_mesh((1.0, 1.0, 1.0), self.divisions, (-0.5, -0.5, -0.5))
        self.connectivity = StaticIndex(conn)
        self.reference_nodes = self.size * jnp.asarray(unit) + self.position0
        self.shape_gradients, self.volumes = jax.vmap(hex8_geometry)(self.reference_nodes[conn])

    def invalid(self) -> str | None:
        for name, value in (("position", self.position0), ("velocity", self.velocity0)):
            if np.shape(value) != (3,):
                return f"{name} must be a vector of 3 coordinates, got shape {np.shape(value)}"
        return None

    @property
    def n_nodes(self) -> int:
        nx, ny, nz = self.divisions
        return (nx + 1) * (ny + 1) * (nz + 1)

    @property
    def n_dof(self) -> int:
        return 3 * self.n_nodes

    @property
    def total_mass(self) -> Scalar:
        """ρ V [kg]."""
        return self.rho * jnp.sum(self.volumes)

    def node(self, i: int, j: int, k: int) -> int:
        """The number of grid node (i, j, k) (static; negative indices count from the last)."""
        nx, ny, nz = self.divisions
        i, j, k = i % (nx + 1), j % (ny + 1), k % (nz + 1)
        return i + (nx + 1) * (j + (ny + 1) * k)

    def node_set(self, name: str) -> tuple[int, ...]:
        """The nodes of face ``name`` (one of :data:`FACES`), in increasing order (static)."""
        if name not in FACES:
            raise ConfigError(f"HexSolid has no face {name!r}; its faces: {', '.join(FACES)}")
        axis, index = FACES[name]
        grid = np.arange(self.n_nodes).reshape(tuple(reversed([d + 1 for d in self.divisions])))  # (k, j, i)
        return tuple(int(n) for n in np.sort(np.take(grid, index, axis=2 - axis).ravel()))

    @property
    def elements(self) -> ElementGroup:
        """The element group: params (dN/dX, dV, λ, μ, ρ), one row per element."""
        conn = self.connectivity.array
        dofs = StaticIndex((3 * conn[:, :, None] + np.arange(3)[None, None, :]).reshape(len(conn), 24))
        lam, mu = lame(self.E, self.nu)
        ne = len(conn)
        params = (self.shape_gradients, self.volumes, *(jnp.broadcast_to(p, (ne,)) for p in (lam, mu, self.rho)))
        return ElementGroup(dofs=dofs, params=params)

    def initial_state(self) -> tuple[Vector, Vector]:
        q0 = self.reference_nodes.reshape(-1)
        return q0, jnp.broadcast_to(self.velocity0, (self.n_nodes, 3)).reshape(-1)

    def mass(self, q: Vector) -> Matrix:
        return self.elements.matrix(hex8_mass, self.n_dof)

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        return self.elements.matrix_product(hex8_mass, x)

    def internal_force(self, q: Vector, v: Vector) -> Vector:
        return self.elements.forces(hex8_internal_force, q, v, self.n_dof)

    def tangents(self, q: Vector, v: Vector) -> tuple[Matrix, Matrix]:
        return self.elements.tangents(hex8_internal_force, q, v, self.n_dof, velocity_dependent=False)

    def element_mass(self, q: Vector) -> ElementMatrix:
        """M element by element (never assembled)."""
        return hex8_mass_blocks(self.elements, self.n_dof)

    def element_stiffness(self, q: Vector) -> ElementMatrix:
        """K(q) element by element (never assembled)."""
        return hex8_stiffness_blocks(self.elements, q, self.n_dof)

    def kronecker_mass(self) -> KroneckerMass:
        """M as a Kronecker product of 1D masses (a box of equal elements,
        uniform ρ), with an exact O(n) product and inverse."""
        return KroneckerMass.of_box(self.size, self.divisions, self.rho)

    def node_dofs(self, nodes: tuple[int, ...]) -> np.ndarray:
        """The coordinates (k, 3) of the nodes ``nodes`` (static): x, y, z of each."""
        return 3 * (np.asarray(nodes)[:, None] % self.n_nodes) + np.arange(3)

    def strain_energy(self, q: Vector) -> Scalar:
        group = self.elements
        return dot_sum(jax.vmap(svk_energy)(group.gather(q), group.params))

    def gravity_force(self, g: Vector) -> Vector:
        """Consistent nodal loads of the acceleration ``g`` (3,), element by element."""
        group = self.elements
        fe = jax.vmap(lambda p: hex8_body_force(p, g))(group.params)
        return jnp.zeros((self.n_dof,), fe.dtype).at[group.dofs.array].add(fe)

    def position(self, q: Vector, at: Vector, node: int | None) -> Vector:
        i = node_index(node if node is not None else 0, self.n_nodes)
        return q[3 * i:3 * i + 3]

    def node_positions(self, q: Vector, nodes: tuple[int, ...]) -> Matrix:
        """Positions (k, 3) [m] of the nodes ``nodes`` (static), in one gather."""
        return q.reshape(-1, 3)[np.asarray(nodes) % self.n_nodes]
