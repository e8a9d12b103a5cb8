"""Redundant bilateral constraints, found on the host before a run.

A bilateral Jacobian G = g_q^B(q0) of shape (nb, n) is *redundant* when its
rank r is below nb: some rows repeat (are combinations of) others, as the
second hinge of a door, a joint pinned twice at one point, or a planar loop
built in 3D. The mechanism is then well posed, its motion unique, but its
multipliers are not: the run takes the minimum-norm ones
(:func:`~nsga_jax._integrators.model_terms.consistent_acceleration`; the
step's sub-problems shift their constraint blocks,
:func:`~nsga_jax._integrators.linalg.redundancy_shift`).

Two checks, in NumPy float64:

* :func:`bilateral_redundancy`: the rank of G from its singular values
  (cut at :data:`RANK_RTOL` times the largest), and which rows are redundant:
  a row is, when it lies (to that cut) in the span of the rows before it, so
  that the later of two identical joints is the one reported; the *parts*
  are those whose rows enter a dependency (a vector of G's left null space).
* :func:`conflict`: whether any position satisfies every bilateral
  constraint, by minimum-norm Gauss-Newton steps ``q -= G⁺ g`` from q0. A
  set stalls at a least-squares point (Gᵀ g = 0) with g ≠ 0 only when its
  rows contradict each other: two welds of one body at different places.

Rows are named ``joints.<name>[i]`` and ``bodies.<name>[i]`` (a body's own
rigidity rows) for a :class:`~nsga_jax.system.SystemModel`, ``bilateral
row j`` for any other model.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

RANK_RTOL = 1e-9
"""Singular values of g_q^B(q0) below this fraction of the largest count as
zero (float64 round-off leaves about 1e-16 on a repeated row)."""

GAUSS_NEWTON_STEPS = 30
"""Most minimum-norm Gauss-Newton steps :func:`conflict` takes."""


class RedundantConstraintsWarning(UserWarning):
    """The bilateral constraints are redundant (:class:`Redundancy`): the run
    goes on, with minimum-norm multipliers."""


class Redundancy(NamedTuple):
    """The redundancy of a bilateral Jacobian at q0.

    Attributes:
        n_rows: nb, the bilateral rows.
        rank: the rank of g_q^B(q0).
        redundant: the names of the nb - rank rows that repeat earlier ones.
        parts: the parts whose rows are linearly dependent (in order).
    """

    n_rows: int
    rank: int
    redundant: tuple[str, ...]
    parts: tuple[str, ...]

    @property
    def n_redundant(self) -> int:
        return self.n_rows - self.rank

    def text(self) -> str:
        return (f"redundant bilateral constraints: g_q^B(q0) has rank {self.rank} for {self.n_rows} rows; "
                f"{self.n_redundant} row(s) repeat others ({', '.join(self.redundant)}) among "
                f"{', '.join(self.parts)}; the run takes the minimum-norm multipliers (the load shared among "
                "the repeated rows, docs/systems.md)")


_terms: Any = None


def bilateral_terms(model, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(g^B(q), g_q^B(q))`` as float64 NumPy arrays, by one program compiled
    once per model structure."""
    global _terms
    import equinox as eqx
    import jax.numpy as jnp

    def terms(m, x):
        return m.bilateral(x), m.bilateral_jacobian(x)

    if _terms is None:
        _terms = eqx.filter_jit(terms)
    g, G = _terms(model, jnp.asarray(q, float))
    return np.asarray(g, float), np.asarray(G, float).reshape(model.n_bilateral, model.n_dof)


def row_names(model) -> list[str]:
    """A name for each bilateral row, from the parts of a system model."""
    names = [f"bilateral row {j}" for j in range(model.n_bilateral)]
    if not (hasattr(model, "joint_names") and hasattr(model, "rows")):
        return names
    start = 0
    for body, name in zip(model.bodies, model.body_names):
        names[start:start + body.n_bilateral] = [f"bodies.{name}[{i}]" for i in range(body.n_bilateral)]
        start += body.n_bilateral
    for name in model.joint_names:
        rows = model.rows("joints", name)
        names[rows] = [f"joints.{name}[{i}]" for i in range(rows.stop - rows.start)]
    return names


def _part(row_name: str) -> str:
    return row_name.split("[")[0]


def _parts(names: list[str], rows: np.ndarray) -> tuple[str, ...]:
    return tuple(dict.fromkeys(_part(names[j]) for j in np.flatnonzero(rows)))


def _rank(G: np.ndarray) -> tuple[int, np.ndarray, float]:
    """Rank, left singular vectors and the cut of G."""
    U, s, _ = np.linalg.svd(G)
    cut = RANK_RTOL * (s[0] if s.size else 0.0)
    return int(np.sum(s > cut)), U, cut


def bilateral_redundancy(model, q0: Any) -> Redundancy | None:
    """The redundancy of g_q^B(q0), or ``None`` when it has full row rank
    (or the model has no bilateral constraint)."""
    if model.n_bilateral == 0:
        return None
    _, G = bilateral_terms(model, np.asarray(q0, float))
    rank, U, cut = _rank(G)
    if rank == G.shape[0]:
        return None
    names = row_names(model)
    basis = np.zeros((0, G.shape[1]))
    redundant = []
    for j, row in enumerate(G):  # in order: a row in the span of the earlier ones is the redundant one
        rest = row - basis.T @ (basis @ row)
        rest = rest - basis.T @ (basis @ rest)  # twice: Gram-Schmidt keeps its orthogonality
        size = np.linalg.norm(rest)
        if size <= cut:
            redundant.append(names[j])
        else:
            basis = np.vstack([basis, rest / size])
    left_null = U[:, rank:]
    dependent = np.linalg.norm(left_null, axis=1) > 1e-8
    return Redundancy(G.shape[0], rank, tuple(redundant), _parts(names, dependent))


def conflict(model, q0: Any, tolerance: float) -> str | None:
    """When the bilateral constraints cannot all hold at any position: a
    message naming the parts that contradict each other (their violation at
    the closest position, in the least-squares sense, above ``tolerance``);
    else ``None`` (they can hold, even if q0 violates them)."""
    if model.n_bilateral == 0:
        return None
    q = np.asarray(q0, float)
    g, G = bilateral_terms(model, q)
    for _ in range(GAUSS_NEWTON_STEPS):
        if np.abs(g).max() <= tolerance:
            return None
        q = q - np.linalg.lstsq(G, g, rcond=RANK_RTOL)[0]  # the minimum-norm step
        g, G = bilateral_terms(model, q)
    stationary = np.linalg.norm(G.T @ g) <= 1e-6 * np.linalg.norm(G) * np.linalg.norm(g)
    if np.abs(g).max() <= tolerance or not stationary:
        return None  # holds, or Gauss-Newton did not settle: q0 is only misplaced
    names = row_names(model)
    parts = _parts(names, np.abs(g) > tolerance)
    listed = parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]
    return (f"{listed} contradict each other: no position satisfies them all (the closest leaves a violation "
            f"of {np.abs(g).max():.3g} m, g = {np.round(g[np.abs(g) > tolerance], 12).tolist()}); redundant "
            "joints are allowed only where they repeat the same constraint (two identical welds, two pins at "
            "one point): place them alike or remove one")


__all__ = ["GAUSS_NEWTON_STEPS", "RANK_RTOL", "Redundancy", "RedundantConstraintsWarning", "bilateral_redundancy",
           "conflict", "row_names"]
