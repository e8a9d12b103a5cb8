"""Bordered iteration matrices of systems of bodies, solved with cost linear
in the number of bodies (paper eqs. 47-49).

A Newton correction solves the bordered system of
:mod:`~nsga_jax._integrators.linalg`; with z = k dμ̃ on the active rows it is

    [ A        -G_upᵀ diag(a) ] [dx]   [ -r₁              ]
    [ diag(a) G_low    εa + 1-a ] [ z] = [ diag(a) r₂ / k   ],     dμ = z / k + (p / k²) r₂,

(ε: the Delassus shift of :func:`~nsga_jax._integrators.linalg.masked_solve`,
relative to an estimate of diag(G A⁻¹ Gᵀ)), the same correction as the
Schur complement on the rows. There, A⁻¹ G_upᵀ and the Delassus matrix
G A⁻¹ Gᵀ are dense even for a chain, whose A (mass, forces, the joints'
curvature) couples neighbouring links only: an LU of about 3N × 3N, a
solve with 2N right-hand sides and an LU of 2N × 2N for N links, O(N³). Here the coordinates and the rows are
ordered body by body, each row placed with the last of its bodies (a
chain's pin with its child link): the bordered matrix is then
block-tridiagonal, the blocks a few bodies with their rows, and
:func:`~nsga_jax._integrators.block_tridiagonal.solve_block_tridiagonal`
solves it in O(N). The matrix's symmetric part, diag(A, ε a + 1 - a), is
positive definite where A's is (G_up = G_low; nearly so in the smooth
motion's eq. 47), so the elimination needs no pivoting across blocks.

Which systems this serves is decided at trace time from the model's
:attr:`~nsga_jax._models.Model.body_coupling` (:func:`block_layout`): the
bodies are ordered along their couplings (their order, or the reverse
Cuthill–McKee one where it is narrower), consecutive bodies merged into
blocks as wide as the coupling reaches, and the layout used where it has
at least :data:`MIN_BLOCKS` blocks; a system with closed loops or branches
gets wider blocks, and one whose bodies all couple stays dense. Friction
keeps the dense path: its semi-smooth correction
(:meth:`~nsga_jax._integrators.friction.FrictionLaw.correction`) works with
the Delassus matrix itself.
"""

from __future__ import annotations

import functools
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import ActiveSet, Matrix, Scalar, Vector
from .._models.coupling import BodyCoupling
from .block_tridiagonal import solve_block_tridiagonal
from .iteration_matrix import AbstractIterationMatrix, BuildElements, BuildMatrix
from .linalg import AbstractFactorisation, redundancy_shift

MIN_BLOCKS = 20
"""The fewest blocks for which the block elimination replaces the dense
factorisations. On a chain of links (``experiments/benchmarks/bench_structured.py``,
docs/performance.md, at d4e5f2a) one correction costs the same both ways
between 8 and 12 links and less from there on (89 against 548 µs at 50); a
whole DS step is faster from 8 links (118 against 147 µs), but its program
compiles up to 0.8 s longer, which a run at 12 links wins back only after
some 12,000 steps.
"""


MAX_BLOCK = 48
"""The largest block the elimination takes: its Gauss–Jordan elimination is
unrolled over the block's unknowns, so a system whose blocks would be larger
(a flexible body of many nodes among the links) keeps the dense path."""


class Gathers(NamedTuple):
    """Where the bordered matrix's entries of a set of block positions come
    from (static flat indices, each with its mask), shape (..., s, s) each:
    A[i, j] (``a``), -G_up[j, i] (``g_up``, the row j's), G_low[i, j]
    (``g_low``, the row i's), the row block's diagonal (``row``) and the
    padding's identity (``pad``)."""

    a: np.ndarray
    a_mask: np.ndarray
    g_up: np.ndarray
    g_up_row: np.ndarray
    g_up_mask: np.ndarray
    g_low: np.ndarray
    g_low_row: np.ndarray
    g_low_mask: np.ndarray
    row: np.ndarray
    row_mask: np.ndarray
    pad: np.ndarray


class BlockLayout(NamedTuple):
    """Where each coordinate and row sits in the block-tridiagonal order (static).

    Attributes:
        unknowns: for each block, its unknowns as indices into ``[dx; z]``
            (coordinates 0..n-1, rows n..n+m-1), negative where padded (a
            distinct number each: the padding is the identity), shape (p, s).
        position: where each unknown of ``[dx; z]`` is in ``unknowns.ravel()``, shape (n + m,).
        gathers: the entries of the diagonal, lower and upper blocks, stacked
            (p + 2 (p - 1), s, s).
        n, m: coordinates and rows.
    """

    unknowns: np.ndarray
    position: np.ndarray
    gathers: Gathers
    n: int
    m: int

    @property
    def blocks(self) -> int:
        return self.unknowns.shape[0]


def _gathers(index: np.ndarray, n: int, m: int) -> Gathers:
    """:class:`Gathers` of the diagonal, lower and upper blocks of ``index``."""
    I = np.concatenate([index[:, :, None], index[1:, :, None], index[:-1, :, None]])
    J = np.concatenate([index[:, None, :], index[:-1, None, :], index[1:, None, :]])
    I, J = np.broadcast_arrays(I, J)
    dof_i, dof_j, row_i, row_j = (I >= 0) & (I < n), (J >= 0) & (J < n), I >= n, J >= n
    ci, cj = np.clip(I, 0, max(n - 1, 0)), np.clip(J, 0, max(n - 1, 0))
    ri, rj = np.clip(I - n, 0, max(m - 1, 0)), np.clip(J - n, 0, max(m - 1, 0))
    return Gathers(a=ci * n + cj, a_mask=dof_i & dof_j, g_up=rj * n + ci, g_up_row=rj, g_up_mask=dof_i & row_j,
                   g_low=ri * n + cj, g_low_row=ri, g_low_mask=row_i & dof_j, row=ri, row_mask=row_i & (I == J),
                   pad=((I < 0) & (I == J)).astype(float))


def _bandwidth(order: np.ndarray, coupled: np.ndarray) -> int:
    position = np.empty_like(order)
    position[order] = np.arange(order.shape[0])
    i, j = np.nonzero(coupled)
    return int(np.abs(position[i] - position[j]).max(initial=0))


def _body_order(coupled: np.ndarray) -> np.ndarray:
    """The bodies' order with the narrower coupling band: as given, or reverse Cuthill–McKee."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    given = np.arange(coupled.shape[0])
    rcm = np.asarray(reverse_cuthill_mckee(csr_matrix(coupled), symmetric_mode=True))
    return rcm if _bandwidth(rcm, coupled) < _bandwidth(given, coupled) else given


@functools.lru_cache(maxsize=128)
def block_layout(coupling: BodyCoupling, n_rows: int) -> BlockLayout | None:
    """The block-tridiagonal layout of a sub-problem with the first ``n_rows``
    constraint rows (module docstring), or ``None`` where it has fewer than
    :data:`MIN_BLOCKS` blocks or one larger than :data:`MAX_BLOCK`."""
    coupled = coupling.coupled_bodies(n_rows)
    order = _body_order(coupled)
    position = np.empty_like(order)
    position[order] = np.arange(order.shape[0])
    width = max(_bandwidth(order, coupled), 1)
    n = coupling.dofs[-1][1] if coupling.dofs else 0
    members: list[list[int]] = [[] for _ in order]
    for body, (start, stop) in enumerate(coupling.dofs):
        members[position[body]].extend(range(start, stop))
    for row, bodies in enumerate(coupling.rows[:n_rows]):
        members[max((position[b] for b in bodies), default=0)].append(n + row)
    blocks = [sum(members[i:i + width], []) for i in range(0, len(members), width)]
    size = max(len(b) for b in blocks)
    if len(blocks) < MIN_BLOCKS or size > MAX_BLOCK:
        return None
    index = -1 - np.arange(len(blocks) * size, dtype=np.int32).reshape(len(blocks), size)  # padding: distinct
    for i, b in enumerate(blocks):
        index[i, :len(b)] = b
    flat = index.ravel()
    position = np.empty(n + n_rows, np.int32)
    position[flat[flat >= 0]] = np.nonzero(flat >= 0)[0]
    return BlockLayout(index, position, _gathers(index, n, n_rows), n, n_rows)


def solve_structured(layout: BlockLayout, A: Matrix, r1: Vector, r2: jax.Array, G_up: jax.Array,
                     G_low: jax.Array, active: ActiveSet, k: Scalar) -> tuple[Vector, jax.Array]:
    """``(dx, z)`` of the bordered system (module docstring) by block elimination.

    Only the entries in the blocks are read (gathers by static flat indices):
    nothing of the size of A or G is formed.

    Args:
        A: the top-left block, shape (n, n).
        r1: coordinate residual, shape (n,); r2: constraint residual, shape (m,).
        G_up, G_low: constraint gradient blocks, shape (m, n).
        active: active-set mask, shape (m,); k: multiplier scaling.
    """
    g, n, m, p = layout.gathers, layout.n, layout.m, layout.blocks
    a = active.astype(A.dtype)
    entries = jnp.where(g.a_mask, A.ravel()[g.a], 0.0) + jnp.asarray(g.pad, A.dtype)
    if m:
        entries = (entries - jnp.where(g.g_up_mask, G_up.ravel()[g.g_up] * a[g.g_up_row], 0.0)
                   + jnp.where(g.g_low_mask, G_low.ravel()[g.g_low] * a[g.g_low_row], 0.0))
        # ε relative to diag(G A⁻¹ Gᵀ), estimated as Σ_j G_rj² / A_jj over the row's entries
        # (in its own block and the one before)
        diagonal = jnp.diagonal(entries[:p], axis1=-2, axis2=-1)  # (p, s): A_jj on coordinates
        safe = jnp.where(jnp.asarray(g.a_mask[:p].diagonal(axis1=-2, axis2=-1)), jnp.abs(diagonal), 1.0)
        low = jnp.where(g.g_low_mask, entries, 0.0) ** 2
        delassus = jnp.max((low[:p] / safe[:, None, :]).sum(-1), initial=0.0)
        if p > 1:
            delassus = jnp.maximum(delassus, jnp.max((low[p:2 * p - 1] / safe[:-1, None, :]).sum(-1)))
        eps = redundancy_shift(A.dtype) * delassus if m > 1 else jnp.zeros((), A.dtype)
        entries = entries + jnp.where(g.row_mask, (a * eps + (1.0 - a))[g.row], 0.0)
    rhs = jnp.concatenate([-r1, a * r2 / k, jnp.zeros((1,), A.dtype)])  # the last: the padding's zero
    x = solve_block_tridiagonal(entries[:p], entries[p:2 * p - 1], entries[2 * p - 1:],
                                rhs[np.where(layout.unknowns < 0, n + m, layout.unknowns)])
    out = x.ravel()[layout.position]
    return out[:n], out[n:]


class StructuredFactorisation(AbstractFactorisation):
    """A top-left block A at one iterate, solved with its rows by block
    elimination (nothing is factored ahead: the elimination is the solve).

    Attributes:
        matrix: A, shape (n, n).
        K_norm, C_norm: ||K||, ||C|| of the tangents A holds (round-off floor).
        coupling: the model's body coupling (static).
    """

    matrix: Matrix
    K_norm: Scalar
    C_norm: Scalar
    coupling: BodyCoupling = eqx.field(static=True)

    def _layout(self, rows: int) -> BlockLayout:
        layout = block_layout(self.coupling, rows)
        assert layout is not None, "Structured is chosen only where the layout has enough blocks"
        return layout

    def solve(self, rhs: jax.Array, bound: Scalar | None = None) -> jax.Array:
        layout = self._layout(0)
        empty = jnp.zeros((0, layout.n), self.matrix.dtype)

        def one(b):  # the bordered system with no rows gives dx = -A⁻¹ r₁
            return -solve_structured(layout, self.matrix, b, empty[:, 0], empty, empty,
                                     jnp.zeros((0,), bool), jnp.ones((), self.matrix.dtype))[0]

        return one(rhs) if rhs.ndim == 1 else jax.vmap(one, in_axes=1, out_axes=1)(rhs)

    def bordered(self, r1: Vector, r2: jax.Array, G_up: jax.Array, G_low: jax.Array, active: ActiveSet,
                 k: Scalar, p: Scalar, bound: Scalar | None = None) -> tuple[Vector, jax.Array]:
        dx, z = solve_structured(self._layout(G_up.shape[0]), self.matrix, r1, r2, G_up, G_low, active, k)
        return dx, z / k + (p / k**2) * r2


class Structured(AbstractIterationMatrix):
    """A evaluated at every Newton iteration and solved with its rows by
    block elimination (:class:`StructuredFactorisation`), for systems whose
    :func:`block_layout` has enough blocks.

    Attributes:
        coupling: the model's body coupling (static).
    """

    coupling: BodyCoupling = eqx.field(static=True)
    is_constant: ClassVar[bool] = False

    def factored(self, build: BuildMatrix, elements: BuildElements | None = None) -> AbstractFactorisation:
        A, K_norm, C_norm = build()
        return StructuredFactorisation(matrix=A, K_norm=K_norm, C_norm=C_norm, coupling=self.coupling)


def structured_applies(coupling: BodyCoupling | None, n_rows: int) -> bool:
    """Whether a model with this coupling solves a sub-problem with ``n_rows``
    rows by block elimination (its :func:`block_layout` has enough blocks)."""
    return coupling is not None and block_layout(coupling, n_rows) is not None


__all__ = ["MAX_BLOCK", "MIN_BLOCKS", "BlockLayout", "Structured", "StructuredFactorisation", "block_layout",
           "solve_structured", "structured_applies"]
