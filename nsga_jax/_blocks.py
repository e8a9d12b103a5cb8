"""Matrices that are never assembled: element blocks, node blocks and
node-local constraint rows, for models too large for dense n × n arrays
(:mod:`~nsga_jax._integrators.krylov`).

- :class:`ElementMatrix`: Σ_e scatter(dofs_e, blocks_e), as a model gives it
  (element by element, :meth:`~nsga_jax._models.Model.element_stiffness`);
- :class:`NodeBlockMatrix`: the same matrix summed into w × w blocks per pair
  of neighbouring nodes (w coordinates a node), each block stored once: a
  product is one gather and one small product per block, no scatter-add,
  which on a CPU measured several times faster than the element-by-element
  product (``experiments/benchmarks/bench_krylov.py``), and the diagonal
  and the Frobenius norm are exact reads;
- :class:`NodeRows`: constraint rows each supported on one node;
- :class:`KroneckerMass`: the mass of a box of equal hexahedra, whose
  product and inverse are Kronecker products of 1D masses.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._assembly import ElementGroup, StaticIndex, scatter_matrix, scatter_vector
from ._custom_types import Matrix, Vector
from ._elements.bar import bar_consistent_mass


class ElementMatrix(eqx.Module):
    """A global matrix Σ_e scatter(dofs_e, blocks_e) kept as its element
    blocks and never assembled: a product is a gather, one small product
    per element and a scatter-add, O(E k²) multiply-adds and storage.

    Attributes:
        blocks: element matrices, shape (E, k, k).
        dofs: element-to-dof map, shape (E, k) (static).
        n: the global size (static).
        width: coordinates a node, numbered node-major (static).
    """

    blocks: jax.Array
    dofs: StaticIndex = eqx.field(static=True)
    n: int = eqx.field(static=True)
    width: int = eqx.field(static=True, default=1)

    def combine(self, a, other: "ElementMatrix", b) -> "ElementMatrix":
        """``a self + b other`` (the same elements)."""
        return ElementMatrix(a * self.blocks + b * other.blocks, self.dofs, self.n, self.width)

    def mv(self, x: Vector) -> Vector:
        """The product with x, shape (n,) -> (n,)."""
        ye = jnp.einsum("eij,ej->ei", self.blocks, x[self.dofs.array])
        return scatter_vector(self.dofs, ye, self.n)

    def diagonal(self) -> Vector:
        """The assembled diagonal, shape (n,)."""
        return scatter_vector(self.dofs, jnp.diagonal(self.blocks, axis1=1, axis2=2), self.n)

    def node_blocks(self) -> "NodeBlockMatrix":
        """The same matrix as w × w node blocks (w = ``width`` coordinates a
        node, numbered node-major: node i holds w i, ..., w i + w - 1)."""
        width = self.width
        layout = node_layout(self.dofs, width)
        E, k = self.dofs.shape
        nodes = k // width
        local = self.blocks.reshape(E, nodes, width, nodes, width).transpose(0, 1, 3, 2, 4)
        blocks = jax.ops.segment_sum(local.reshape(-1, width, width), jnp.asarray(layout.slot_of_entry),
                                     num_segments=layout.neighbours.size)
        return NodeBlockMatrix(blocks.reshape(*layout.neighbours.shape, width, width), layout.neighbours_index,
                               self.n)

    def dense(self) -> Matrix:
        """The assembled matrix (n, n), for checks on small models."""
        return scatter_matrix(self.dofs, self.blocks, self.n)


class NodeRows(eqx.Module):
    """Constraint rows (m, n) each supported on a few coordinates (one node's):
    row i is ``vals[i]`` on the columns ``cols[i]``. ``G @ x``, ``G.T @ y`` and
    ``abs(G)`` read as for a dense array, so the sub-problems use either.

    Attributes:
        vals: the rows' values, shape (m, w).
        cols: their columns, shape (m, w) (static).
        n: the number of coordinates (static).
    """

    vals: jax.Array
    cols: StaticIndex = eqx.field(static=True)
    n: int = eqx.field(static=True)

    @property
    def shape(self) -> tuple[int, int]:
        return (self.vals.shape[0], self.n)

    def __matmul__(self, x: Vector) -> jax.Array:
        return jnp.sum(self.vals * x[self.cols.array], axis=-1)

    def __abs__(self) -> "NodeRows":
        return NodeRows(jnp.abs(self.vals), self.cols, self.n)

    @property
    def T(self) -> "_TransposedRows":
        return _TransposedRows(self)

    def orthonormal(self) -> bool:
        """Whether the rows' supports make them orthonormal when each row has
        unit norm and a node's rows are orthogonal (static): rows that share a
        column share all their columns (one node's), at most w of them (a
        node's coordinate axes: a pinned node), else no two rows share a
        column (one contact a node). :func:`~nsga_jax.check_model` checks
        G Gᵀ = I on the values."""
        cols = self.cols.array
        if cols.shape[0] == 0:
            return True
        supports, counts = np.unique(np.sort(cols, axis=1), axis=0, return_counts=True)
        flat = supports.ravel()
        return len(np.unique(flat)) == len(flat) and int(counts.max()) <= cols.shape[1]

    def rows(self, start: int, stop: int) -> "NodeRows":
        """Rows ``start`` to ``stop`` (static), as ``G[start:stop]`` of a dense array."""
        return NodeRows(self.vals[start:stop], StaticIndex(self.cols.array[start:stop]), self.n)

    def dense(self) -> Matrix:
        """The rows as a dense (m, n) array, for checks on small models."""
        m = self.vals.shape[0]
        return jnp.zeros((m, self.n), self.vals.dtype).at[np.arange(m)[:, None], self.cols.array].add(self.vals)


class _TransposedRows(eqx.Module):
    """``G.T`` of :class:`NodeRows`: ``G.T @ y`` scatters y (m,) into (n,)."""

    rows: NodeRows

    def __matmul__(self, y: jax.Array) -> Vector:
        r = self.rows
        return jnp.zeros((r.n,), r.vals.dtype).at[r.cols.array].add(r.vals * y[:, None])


class NodeLayout(NamedTuple):
    """Where element blocks land among node blocks (static, from the element-to-dof map).

    Attributes:
        neighbours: for each node, the nodes it shares an element with, padded
            with its own number, shape (N, P).
        neighbours_index: the same, hashable (a static field).
        slot_of_entry: for each element's node pair (e, a, b), the flat slot
            ``i P + s`` of node b in node a's neighbours, shape (E k_n²,).
    """

    neighbours: np.ndarray
    neighbours_index: StaticIndex
    slot_of_entry: np.ndarray


@functools.lru_cache(maxsize=32)
def node_layout(dofs: StaticIndex, width: int) -> NodeLayout:
    """The node-block layout of element blocks on ``dofs`` (E, k), ``width`` coordinates a node."""
    idx = dofs.array
    E, k = idx.shape
    enodes = idx[:, ::width] // width
    expected = (width * enodes[:, :, None] + np.arange(width)).reshape(E, k)
    if not np.array_equal(idx, expected):
        raise ValueError(f"element dofs are not {width} consecutive coordinates a node")
    n_nodes = int(idx.max()) // width + 1
    rows = np.repeat(enodes, enodes.shape[1], axis=1).ravel().astype(np.int64)
    cols = np.tile(enodes, (1, enodes.shape[1])).ravel().astype(np.int64)
    pairs, inverse = np.unique(rows * n_nodes + cols, return_inverse=True)
    pair_row = pairs // n_nodes
    counts = np.bincount(pair_row, minlength=n_nodes)
    P = int(counts.max())
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.arange(len(pairs)) - start[pair_row]  # pairs are sorted by row, then column
    neighbours = np.repeat(np.arange(n_nodes)[:, None], P, axis=1)
    neighbours[pair_row, slot] = pairs % n_nodes
    flat_slot = (pair_row * P + slot)[inverse]
    return NodeLayout(neighbours, StaticIndex(neighbours), flat_slot.astype(np.int32))


class NodeBlockMatrix(eqx.Module):
    """A sparse matrix of w × w blocks between neighbouring nodes, each stored once.

    Attributes:
        blocks: block s of node i couples it to node ``neighbours[i, s]``,
            shape (N, P, w, w) (zero blocks pad nodes with fewer neighbours).
        neighbours: shape (N, P) (static).
        n: the number of coordinates, N w (static).
    """

    blocks: jax.Array
    neighbours: StaticIndex = eqx.field(static=True)
    n: int = eqx.field(static=True)

    def mv(self, x: Vector) -> Vector:
        """The product with x, shape (n,) -> (n,): one gather, no scatter."""
        N, P, w, _ = self.blocks.shape
        xs = x.reshape(-1, w)[self.neighbours.array]  # (N, P, w)
        return jnp.einsum("npij,npj->ni", self.blocks, xs).reshape(N * w)

    def diagonal(self) -> Vector:
        """The diagonal, shape (n,): each node's own block (its first neighbour)."""
        N, P, w, _ = self.blocks.shape
        own = self.neighbours.array == np.arange(N)[:, None]
        first = np.argmax(own, axis=1)
        return jnp.diagonal(self.blocks[np.arange(N), first], axis1=1, axis2=2).reshape(N * w)

    def frobenius_norm(self) -> jax.Array:
        """The Frobenius norm, exactly (every entry is stored once)."""
        return jnp.linalg.norm(self.blocks)

    def combine(self, a, other: "NodeBlockMatrix", b) -> "NodeBlockMatrix":
        """``a self + b other`` (the same layout)."""
        return NodeBlockMatrix(a * self.blocks + b * other.blocks, self.neighbours, self.n)

    def dense(self) -> Matrix:
        """The assembled matrix (n, n), for checks on small models."""
        N, P, w, _ = self.blocks.shape
        rows = (w * np.arange(N)[:, None, None, None] + np.arange(w)[:, None]).repeat(P, 1)
        cols = w * self.neighbours.array[:, :, None, None] + np.arange(w)[None, :]
        rows = np.broadcast_to(rows, (N, P, w, w))
        cols = np.broadcast_to(cols, (N, P, w, w))
        return jnp.zeros((self.n, self.n), self.blocks.dtype).at[rows, cols].add(self.blocks)


class KroneckerMass(eqx.Module):
    """The consistent mass of a box meshed with equal trilinear hexahedra and
    a uniform density, M = ρ (M_z ⊗ M_y ⊗ M_x) ⊗ I_3, with M_a the 1D mass of
    linear elements along axis a (nodes numbered x fastest): M x and M⁻¹ x
    are each three products with (n_a + 1) × (n_a + 1) matrices, O(n (n_x +
    n_y + n_z)) multiply-adds, where the node blocks' product gathers 27
    neighbours a node (``experiments/benchmarks/bench_large_kernels.py``).

    Attributes:
        masses: (M_z, M_y, M_x), the 1D masses per unit density [m].
        inverses: their inverses.
        density: ρ [kg/m³], times the scale of :meth:`scaled`.
    """

    masses: tuple[jax.Array, jax.Array, jax.Array]
    inverses: tuple[jax.Array, jax.Array, jax.Array]
    density: jax.Array

    @classmethod
    def of_box(cls, size: jax.Array, divisions: tuple[int, int, int], density: jax.Array) -> "KroneckerMass":
        """From the box's side lengths (3,) [m], its element counts (x, y, z) and ρ."""
        def mass_1d(length, n):  # n linear elements of unit density: the bar's consistent mass
            le = jnp.broadcast_to(length / n, (n,))
            chain = ElementGroup(StaticIndex(np.stack([np.arange(n), np.arange(1, n + 1)], axis=1)),
                                 (jnp.ones_like(le), le, jnp.ones_like(le)))
            return chain.matrix(bar_consistent_mass, n + 1)

        x, y, z = (mass_1d(size[a], divisions[a]) for a in range(3))
        return cls((z, y, x), (jnp.linalg.inv(z), jnp.linalg.inv(y), jnp.linalg.inv(x)), jnp.asarray(density))

    @staticmethod
    def _kron(factors: tuple[jax.Array, jax.Array, jax.Array], r: Vector) -> Vector:
        z, y, x = factors
        R = r.reshape(z.shape[0], y.shape[0], x.shape[0], 3)
        R = jnp.einsum("kl,ljic->kjic", z, R)
        R = jnp.einsum("jl,klic->kjic", y, R)
        R = jnp.einsum("il,kjlc->kjic", x, R)
        return R.reshape(-1)

    def mv(self, x: Vector) -> Vector:
        """M x, shape (n,) -> (n,)."""
        return self.density * self._kron(self.masses, x)

    def solve(self, r: Vector) -> Vector:
        """M⁻¹ r, shape (n,) -> (n,)."""
        return self._kron(self.inverses, r) / self.density

    def diagonal(self) -> Vector:
        """The diagonal of M, shape (n,)."""
        z, y, x = (jnp.diagonal(m) for m in self.masses)
        return self.density * jnp.repeat(jnp.einsum("k,j,i->kji", z, y, x).reshape(-1), 3)

    def scaled(self, c) -> "KroneckerMass":
        """c M."""
        return KroneckerMass(self.masses, self.inverses, c * self.density)
