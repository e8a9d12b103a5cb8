"""Finite-element style assembly: one ``vmap`` per element group, scatter-add.

An element is a pure function of its own coordinates, velocities and
parameters. Its tangents come from ``jax.jacfwd`` at element level; global
vectors and matrices are assembled by scatter-add over the element-to-dof map.

A 1D chain, whose element e holds the s coordinates of nodes e and e + 1
(the bar, s = 1; the planar beam, s = 3), is recognised from its static
element-to-dof map (:func:`chain_layout`), and its matrices (the tangents a
nonlinear beam assembles at every Newton iteration) are laid out with pads
and reshapes instead of a scatter-add: the same sums (a diagonal block
receives exactly two contributions, and two-term sums do not depend on their
order), in operations the compiler fuses. On the flexible pendulum a step
took 33-37 µs against 46-62 with the scatter-add, for the same compile work
(``experiments/tools/compare_revisions.py``, 2-core CPU). (Vectors keep the gather
and the scatter: slicing them measured no faster.)
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._compat import dot_sum
from ._custom_types import Matrix, Scalar, Vector

ElementForce = Callable[[jax.Array, jax.Array, Any], jax.Array]
"""``f_e = element_force(x_e, v_e, params_e)``: element coordinates and
velocities (shape (k,)) and the element's parameters -> element force (k,)."""


class StaticIndex:
    """A hashable, immutable integer array, usable as a static (trace-time) field."""

    __slots__ = ("_bytes", "_shape")

    def __init__(self, array):
        a = np.ascontiguousarray(np.asarray(array, dtype=np.int32))
        self._bytes = a.tobytes()
        self._shape = a.shape

    @property
    def array(self) -> np.ndarray:
        return np.frombuffer(self._bytes, dtype=np.int32).reshape(self._shape)

    @property
    def shape(self) -> tuple[int, ...]:
        return self._shape

    def __hash__(self) -> int:
        return hash((self._bytes, self._shape))

    def __eq__(self, other) -> bool:
        return (
            isinstance(other, StaticIndex)
            and self._shape == other._shape
            and self._bytes == other._bytes
        )

    def __repr__(self) -> str:
        return f"StaticIndex(shape={self._shape})"


class ElementGroup(eqx.Module):
    """Elements of one type.

    Attributes:
        dofs: element-to-global-dof map, shape (n_elements, k), static.
        params: pytree of element parameters; every array leaf has a leading
            axis of length n_elements (one vmap evaluates the whole group).
    """

    dofs: StaticIndex = eqx.field(static=True)
    params: Any

    @property
    def n_elements(self) -> int:
        return self.dofs.shape[0]

    def gather(self, x: Vector) -> jax.Array:
        """Element coordinates, shape (n_elements, k)."""
        return x[self.dofs.array]

    def forces(self, fn: ElementForce, q: Vector, v: Vector, n: int) -> Vector:
        """Assembled element forces, shape (n,)."""
        fe = _vmapped(fn)(self.gather(q), self.gather(v), self.params)
        return scatter_vector(self.dofs, fe, n)

    def tangents(
        self, fn: ElementForce, q: Vector, v: Vector, n: int, velocity_dependent: bool = True
    ) -> tuple[Matrix, Matrix]:
        """Assembled K = -df/dq and C = -df/dv from element-level ``jacfwd``
        (C is not formed, and returned as zeros, when ``velocity_dependent`` is False)."""
        xe, ve = self.gather(q), self.gather(v)
        K = scatter_matrix(self.dofs, self.stiffness_blocks(fn, q, v), n)
        if not velocity_dependent:
            return K, jnp.zeros_like(K)
        Ce = -_vmapped_jacobian(fn, 1)(xe, ve, self.params)
        return K, scatter_matrix(self.dofs, Ce, n)

    def stiffness_blocks(self, fn: ElementForce, q: Vector, v: Vector) -> jax.Array:
        """Element tangents K_e = -df_e/dx_e from element-level ``jacfwd``, shape (n_elements, k, k)."""
        return -_vmapped_jacobian(fn, 0)(self.gather(q), self.gather(v), self.params)

    def matrix_blocks(self, fn: Callable[[Any], jax.Array]) -> jax.Array:
        """Element matrices ``fn(params_e)`` (e.g. mass), shape (n_elements, k, k)."""
        return jax.vmap(fn)(self.params)

    def matrix_product(self, fn: Callable[[Any], jax.Array], x: Vector) -> Vector:
        """Assembled ``sum_e fn(params_e) @ x_e`` without forming the global matrix."""
        ye = jax.vmap(lambda p, xe: fn(p) @ xe)(self.params, self.gather(x))
        return scatter_vector(self.dofs, ye, x.shape[0])

    def quadratic_form(self, fn: Callable[[Any], jax.Array], x: Vector) -> Scalar:
        """``Σ_e x_eᵀ fn(params_e) x_e`` (``xᵀ A x`` of the assembled matrix A;
        twice the kinetic energy for the mass), never assembled: for a chain of
        2-node elements, element by element from its nodes read by slices;
        otherwise ``x · (A x)`` by the element products."""
        chain = chain_layout(self.dofs)
        if chain is None:  # measured faster than element by element (experiments/benchmarks/bench_energy.py)
            return x @ self.matrix_product(fn, x)
        blocks = self.matrix_blocks(fn)  # (n_elements, k, k)
        offset, s = chain
        nodes = x[offset:offset + (self.n_elements + 1) * s].reshape(-1, s).T  # (s, n_nodes)
        xe = [nodes[i, :-1] for i in range(s)] + [nodes[i, 1:] for i in range(s)]  # k rows (n_elements,)
        a = jnp.moveaxis(blocks, 0, -1)  # (k, k, n_elements)
        terms = [a[i, j] * xe[i] * xe[j] for i in range(2 * s) for j in range(2 * s)]
        return dot_sum(functools.reduce(jnp.add, terms))

    def matrix(self, fn: Callable[[Any], jax.Array], n: int) -> Matrix:
        """Assembled element matrices ``fn(params_e)`` (e.g. mass), shape (n, n)."""
        return scatter_matrix(self.dofs, self.matrix_blocks(fn), n)


# A step evaluates the same element force (and its Jacobian) in several places
# (residuals, tangents, predictor). Behind one jit per element function, each is
# traced once per shape and reused; XLA inlines the calls, so the compiled code
# is the same, and tracing a beam or hex step takes about half the time.


@functools.cache
def _vmapped(fn: ElementForce):
    """``fn`` over a group's elements."""
    return jax.jit(jax.vmap(fn))


@functools.cache
def _vmapped_jacobian(fn: ElementForce, argnums: int):
    """The Jacobian of ``fn`` in its argument ``argnums``, over a group's elements."""
    return jax.jit(jax.vmap(jax.jacfwd(fn, argnums=argnums)))


@functools.lru_cache(maxsize=256)
def chain_layout(dofs: StaticIndex) -> tuple[int, int] | None:
    """``(offset, s)`` when element e's dofs are ``offset + s e + [0, ..., 2s - 1]``
    (a chain of 2-node elements with s dofs per node), else ``None``."""
    idx = dofs.array
    if idx.ndim != 2 or idx.shape[0] < 1 or idx.shape[1] % 2:
        return None
    n_el, k = idx.shape
    s = k // 2
    offset = int(idx[0, 0])
    expected = offset + s * np.arange(n_el)[:, None] + np.arange(k)[None, :]
    return (offset, s) if np.array_equal(idx, expected) else None


def scatter_vector(dofs: StaticIndex, values: jax.Array, n: int) -> Vector:
    """Sum element vectors (n_el, k) into a global vector (n,)."""
    return jnp.zeros((n,), values.dtype).at[dofs.array].add(values)


def scatter_matrix(dofs: StaticIndex, values: jax.Array, n: int) -> Matrix:
    """Sum element matrices (n_el, k, k) into a dense global matrix (n, n)."""
    chain = chain_layout(dofs)
    if chain is None:
        idx = dofs.array
        return jnp.zeros((n, n), values.dtype).at[idx[:, :, None], idx[:, None, :]].add(values)
    # a chain's matrix is block-tridiagonal: row block i holds the node blocks
    # (i, i - 1), (i, i) and (i, i + 1), each a single element block except
    # the diagonal ones, sums of two
    offset, s = chain
    n_nodes = values.shape[0] + 1
    first, second = (0, 1), (1, 0)  # padding over nodes: an element block lands on its first / second node
    diagonal = (jnp.pad(values[:, :s, :s], [first, (0, 0), (0, 0)])
                + jnp.pad(values[:, s:, s:], [second, (0, 0), (0, 0)]))
    upper = jnp.pad(values[:, :s, s:], [first, (0, 0), (0, 0)])  # block (e, e + 1), in row block e
    lower = jnp.pad(values[:, s:, :s], [second, (0, 0), (0, 0)])  # block (e + 1, e), in row block e + 1
    rows = jnp.concatenate([lower, diagonal, upper], axis=2)  # (N, s, 3s): columns of nodes i - 1, i, i + 1
    # skew: padded to (N + 3) s columns and read back (N + 2) s wide, row block i starts at column i s
    width = (n_nodes + 2) * s
    rows = jnp.pad(jnp.swapaxes(rows, 0, 1), [(0, 0), (0, 0), (0, n_nodes * s)]).reshape(s, -1)
    skewed = rows[:, : n_nodes * width].reshape(s, n_nodes, width)[:, :, s:(n_nodes + 1) * s]
    dense = jnp.swapaxes(skewed, 0, 1).reshape(n_nodes * s, n_nodes * s)
    tail = n - offset - n_nodes * s
    return jnp.pad(dense, [(offset, tail), (offset, tail)])
