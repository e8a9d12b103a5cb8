"""Flexible bodies of a system, assembled from the element library
(:mod:`nsga_jax._elements`) element by element (:mod:`nsga_jax._assembly`).

Their material points are nodes, named by index (``node = i``; negative
indices count from the last node, ``-1`` the tip).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._assembly import ElementGroup, StaticIndex
from .._blocks import ElementMatrix
from .._compat import dot_sum
from .._custom_types import Matrix, Scalar, Vector
from .._elements.bar import bar_consistent_mass, bar_internal_force, bar_lumped_mass
from .._elements.beam2d import beam_energy, beam_internal_force, beam_mass
from .._models.base import count_rule
from .._util import as_float
from .._validation import POSITIVE, Range
from .base import AbstractBody


def node_index(node: int, n_nodes: int) -> int:
    """A node index with negative ones counted from the end (static)."""
    return node % n_nodes


class Beam2D(AbstractBody):
    """A straight planar geometrically exact (Reissner) beam of ``n_elements``
    two-node elements (:mod:`nsga_jax._elements.beam2d`), initially unstressed.

    Coordinates: per node (x, y, θ) [m, m, rad], node-major, node 0 at the
    root. In its initial configuration the beam leaves ``position`` (the
    root, (2,)) along ``angle`` [rad], moving rigidly with the root's
    ``velocity`` (2,) [m/s] and ``angular_velocity`` [rad/s] about the root.

    Attributes:
        E [Pa], nu (Poisson's ratio, for the shear modulus G = E / (2 (1 + ν))),
        rho [kg/m³], area A [m²], second_moment I [m⁴], shear_factor As/A,
        length [m].
        n_elements: element count (static); lumped: lumped mass matrix (static).
    """

    E: Scalar = eqx.field(converter=as_float)
    nu: Scalar = eqx.field(converter=as_float)
    rho: Scalar = eqx.field(converter=as_float)
    area: Scalar = eqx.field(converter=as_float)
    second_moment: Scalar = eqx.field(converter=as_float)
    length: Scalar = eqx.field(converter=as_float)
    position0: Vector = eqx.field(converter=as_float)
    angle0: Scalar = eqx.field(converter=as_float)
    velocity0: Vector = eqx.field(converter=as_float)
    angular_velocity0: Scalar = eqx.field(converter=as_float)
    shear_factor: Scalar = eqx.field(converter=as_float)
    n_elements: int = eqx.field(static=True)
    lumped: bool = eqx.field(static=True)

    ranges = {"E": POSITIVE, "nu": Range(-1.0, 0.5, lo_open=True, hi_open=True), "rho": POSITIVE,
              "area": POSITIVE, "second_moment": POSITIVE, "length": POSITIVE,
              "shear_factor": Range(0.0, 1.0, lo_open=True)}
    linear_force = False
    has_nodes = True

    def __init__(self, E, nu, rho, area, second_moment, length, n_elements, position=(0.0, 0.0), angle=0.0,
                 velocity=(0.0, 0.0), angular_velocity=0.0, shear_factor=5.0 / 6.0, lumped=False):
        self.E, self.nu, self.rho = as_float(E), as_float(nu), as_float(rho)
        self.area, self.second_moment, self.length = as_float(area), as_float(second_moment), as_float(length)
        self.position0, self.angle0 = as_float(position), as_float(angle)
        self.velocity0, self.angular_velocity0 = as_float(velocity), as_float(angular_velocity)
        self.shear_factor = as_float(shear_factor)
        self.n_elements, self.lumped = n_elements, bool(lumped)

    def invalid(self) -> str | None:
        if isinstance(self.n_elements, bool) or not isinstance(self.n_elements, (int, np.integer)) \
                or self.n_elements < 1:
            return f"n_elements must be an integer >= 1, got {self.n_elements!r}"
        for name, value in (("position", self.position0), ("velocity", self.velocity0)):
            if np.shape(value) != (2,):
                return f"{name} must be a vector of 2 coordinates, got shape {np.shape(value)}"
        return None

    dim = 2  # type: ignore[assignment]

    @property
    def n_nodes(self) -> int:
        return self.n_elements + 1

    @property
    def n_dof(self) -> int:
        return 3 * self.n_nodes

    @property
    def bandwidth(self) -> int:
        return 5  # two-node elements of 3 dofs per node: block tridiagonal

    @property
    def total_mass(self) -> Scalar:
        return self.rho * self.area * self.length

    @property
    def elements(self) -> ElementGroup:
        """The element group: params (EA, GAs, EI, L0, ρA, ρI, θ0), one row per element."""
        ne = self.n_elements
        A, I = self.area, self.second_moment
        G = self.E / (2.0 * (1.0 + self.nu))
        dofs = StaticIndex(3 * np.arange(ne)[:, None] + np.arange(6)[None, :])
        values = (self.E * A, G * self.shear_factor * A, self.E * I, self.length / ne, self.rho * A,
                  self.rho * I, self.angle0)
        return ElementGroup(dofs=dofs, params=tuple(jnp.broadcast_to(p, (ne,)) for p in values))

    def reference(self) -> Vector:
        """The initial (straight, unstressed) coordinates (n,)."""
        s = jnp.linspace(0.0, 1.0, self.n_nodes) * self.length
        x = self.position0[0] + s * jnp.cos(self.angle0)
        y = self.position0[1] + s * jnp.sin(self.angle0)
        return jnp.stack([x, y, jnp.full_like(s, self.angle0)], axis=1).reshape(-1)

    def initial_state(self) -> tuple[Vector, Vector]:
        q0 = self.reference()
        nodes = q0.reshape(-1, 3)
        r = nodes[:, :2] - self.position0
        w = self.angular_velocity0
        v = self.velocity0 + w * jnp.stack([-r[:, 1], r[:, 0]], axis=1)
        return q0, jnp.concatenate([v, jnp.broadcast_to(w, (self.n_nodes, 1))], axis=1).reshape(-1)

    def mass(self, q: Vector) -> Matrix:
        return self.elements.matrix(lambda p: beam_mass(p, self.lumped), self.n_dof)

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        return self.elements.matrix_product(lambda p: beam_mass(p, self.lumped), x)

    def kinetic_energy(self, q: Vector, v: Vector) -> Scalar:
        return 0.5 * self.elements.quadratic_form(lambda p: beam_mass(p, self.lumped), v)

    def internal_force(self, q: Vector, v: Vector) -> Vector:
        return self.elements.forces(beam_internal_force, q, v, self.n_dof)

    def tangents(self, q: Vector, v: Vector) -> tuple[Matrix, Matrix]:
        return self.elements.tangents(beam_internal_force, q, v, self.n_dof, velocity_dependent=False)

    def strain_energy(self, q: Vector) -> Scalar:
        return dot_sum(jax.vmap(beam_energy)(self.elements.gather(q), self.elements.params))

    def gravity_force(self, g: Vector) -> Vector:
        """Consistent nodal loads ρA g l_e / 2 from each element on its two nodes' (x, y)."""
        ne = self.n_elements
        le = self.length / ne
        weights = jnp.full((ne + 1,), le).at[0].set(le / 2).at[-1].set(le / 2)
        f = jnp.zeros((ne + 1, 3), weights.dtype)
        f = f.at[:, 0].set(self.rho * self.area * g[0] * weights).at[:, 1].set(self.rho * self.area * g[1] * weights)
        return f.reshape(-1)

    def position(self, q: Vector, at: Vector, node: int | None) -> Vector:
        i = node_index(node if node is not None else 0, self.n_nodes)
        return q[3 * i:3 * i + 2]

    def angle(self, q: Vector, node: int | None) -> Scalar:
        i = node_index(node if node is not None else 0, self.n_nodes)
        return q[3 * i + 2]

    def angular_speed(self, q: Vector, v: Vector) -> Scalar:
        return jnp.max(jnp.abs(v[2::3]))


class Bar(AbstractBody):
    """A straight uniform bar of ``n_elements`` linear two-node elements
    (:mod:`nsga_jax._elements.bar`) moving along its axis, in one dimension.

    Coordinates: the nodal axial displacements u (n_elements + 1,) [m], node
    0 at ``position``. Node i's reference is ``X_i = position + i L / n`` and
    its position ``X_i + u_i``. M and K are constant and tridiagonal
    (``bandwidth`` 1): a linear system of bars takes the integrator's
    tridiagonal path.

    Attributes:
        E [Pa], rho [kg/m³], area [m²], length L [m].
        position: x of node 0 in the reference configuration [m].
        velocity: uniform initial velocity [m/s].
        n_elements: element count (static); lumped: lumped mass matrix (static).
    """

    E: Scalar = eqx.field(converter=as_float)
    rho: Scalar = eqx.field(converter=as_float)
    area: Scalar = eqx.field(converter=as_float)
    length: Scalar = eqx.field(converter=as_float)
    position0: Scalar = eqx.field(converter=as_float)
    velocity0: Scalar = eqx.field(converter=as_float)
    n_elements: int = eqx.field(static=True)
    lumped: bool = eqx.field(static=True)

    ranges = {"E": POSITIVE, "rho": POSITIVE, "area": POSITIVE, "length": POSITIVE}
    has_nodes = True
    dim = 1  # type: ignore[assignment]

    def __init__(self, E, rho, area, length, n_elements, position=0.0, velocity=0.0, lumped=False):
        self.E, self.rho, self.area, self.length = as_float(E), as_float(rho), as_float(area), as_float(length)
        self.position0, self.velocity0 = as_float(position), as_float(velocity)
        self.n_elements, self.lumped = n_elements, bool(lumped)

    def invalid(self) -> str | None:
        for name, value in (("position", self.position0), ("velocity", self.velocity0)):
            if np.ndim(value) != 0:
                return f"{name} must be a number (the bar moves along x), got shape {np.shape(value)}"
        return count_rule("n_elements", self.n_elements)

    @property
    def n_nodes(self) -> int:
        return self.n_elements + 1

    @property
    def n_dof(self) -> int:
        return self.n_nodes

    @property
    def bandwidth(self) -> int:
        return 1  # two-node elements on consecutive coordinates: M and K are tridiagonal

    @property
    def total_mass(self) -> Scalar:
        return self.rho * self.area * self.length

    @property
    def elements(self) -> ElementGroup:
        """The element group: params (EA, l_e, ρA), one row per element."""
        ne = self.n_elements
        dofs = StaticIndex(np.stack([np.arange(ne), np.arange(1, ne + 1)], axis=1))
        params = tuple(jnp.broadcast_to(p, (ne,)) for p in (self.E * self.area, self.length / ne, self.rho * self.area))
        return ElementGroup(dofs=dofs, params=params)

    @property
    def _element_mass(self):
        return bar_lumped_mass if self.lumped else bar_consistent_mass

    def reference(self, node: int) -> Scalar:
        """X_i = position + i L / n [m], the reference x of node ``node`` (static)."""
        i = node_index(node, self.n_nodes)
        return self.position0 + self.length * (i / self.n_elements)

    def initial_state(self) -> tuple[Vector, Vector]:
        v0 = jnp.broadcast_to(self.velocity0, (self.n_nodes,))
        return jnp.zeros_like(v0), v0

    def mass(self, q: Vector) -> Matrix:
        return self.elements.matrix(self._element_mass, self.n_dof)

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        return self.elements.matrix_product(self._element_mass, x)

    def kinetic_energy(self, q: Vector, v: Vector) -> Scalar:
        return 0.5 * self.elements.quadratic_form(self._element_mass, v)

    def internal_force(self, q: Vector, v: Vector) -> Vector:
        return self.elements.forces(bar_internal_force, q, v, self.n_dof)

    def tangents(self, q: Vector, v: Vector) -> tuple[Matrix, Matrix]:
        return self.elements.tangents(bar_internal_force, q, v, self.n_dof, velocity_dependent=False)

    def element_mass(self, q: Vector) -> ElementMatrix:
        """M element by element (never assembled), one coordinate a node."""
        group = self.elements
        return ElementMatrix(group.matrix_blocks(self._element_mass), group.dofs, self.n_dof)

    def element_stiffness(self, q: Vector) -> ElementMatrix:
        """K element by element (constant, never assembled), one coordinate a node."""
        group = self.elements
        return ElementMatrix(group.stiffness_blocks(bar_internal_force, q, jnp.zeros_like(q)), group.dofs, self.n_dof)

    def node_dofs(self, nodes: tuple[int, ...]) -> np.ndarray:
        """The coordinates (k, 1) of the nodes ``nodes`` (static): the axial displacement of each."""
        return (np.asarray(nodes) % self.n_nodes)[:, None]

    def strain_energy(self, q: Vector) -> Scalar:
        """Σ_e EA (u_{e+1} - u_e)² / (2 l_e) [J]."""
        EA, le, _ = self.elements.params
        return dot_sum(0.5 * EA / le * (q[1:] - q[:-1]) ** 2)

    def gravity_force(self, g: Vector) -> Vector:
        """Consistent nodal loads ρA g l_e / 2 from each element on its two nodes."""
        ne = self.n_elements
        le = self.length / ne
        weights = jnp.full((ne + 1,), le).at[0].set(le / 2).at[-1].set(le / 2)
        return self.rho * self.area * g[0] * weights

    def position(self, q: Vector, at: Vector, node: int | None) -> Vector:
        i = node_index(node if node is not None else 0, self.n_nodes)
        return (self.reference(i).astype(q.dtype) + q[i])[None]
