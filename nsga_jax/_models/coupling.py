"""Which coordinates a model's matrices couple: its bodies and the bodies of
each constraint row (static structure, known before anything is traced).

A system of bodies and joints (:class:`~nsga_jax._system.model.SystemModel`)
couples a body's coordinates only with themselves through the mass, with
another body's only through a force acting on both or a constraint row that
moves both: the iteration matrices of a chain of links are then
block-tridiagonal once their coordinates and rows are ordered along the
chain (:mod:`~nsga_jax._integrators.structured`). A model that declares its
coupling has it checked by :func:`~nsga_jax._models.check.check_model`:
M, K, C zero between uncoupled bodies, each row of g_q zero outside its
bodies' coordinates.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class BodyCoupling(NamedTuple):
    """The coupling pattern of a model's coordinates and constraint rows (static, hashable).

    Attributes:
        dofs: each body's coordinates as ``(start, stop)``, in order, covering 0..n.
        rows: for each constraint row of ``[g^B; g^U]`` (in order), the bodies
            (indices into ``dofs``) whose coordinates it depends on.
        pairs: pairs of bodies coupled by a force (K or C), ``(i, j)`` with i < j.
    """

    dofs: tuple[tuple[int, int], ...]
    rows: tuple[tuple[int, ...], ...]
    pairs: tuple[tuple[int, int], ...]

    def body_of_dof(self) -> np.ndarray:
        """The body of each coordinate, shape (n,)."""
        return np.concatenate([np.full(stop - start, i) for i, (start, stop) in enumerate(self.dofs)]
                              or [np.zeros(0, int)]).astype(int)

    def coupled_bodies(self, n_rows: int) -> np.ndarray:
        """Which bodies the matrices of a sub-problem with the first ``n_rows``
        rows couple (mass, forces, and the curvature of each row between its
        bodies), shape (bodies, bodies), bool."""
        nb = len(self.dofs)
        out = np.eye(nb, dtype=bool)
        for i, j in self.pairs:
            out[i, j] = out[j, i] = True
        for bodies in self.rows[:n_rows]:
            for i in bodies:
                for j in bodies:
                    out[i, j] = True
        return out

    def allowed_matrix(self, n_rows: int = 0) -> np.ndarray:
        """Where M, K and C (and the rows' curvature) may be non-zero, shape (n, n), bool."""
        body = self.body_of_dof()
        return self.coupled_bodies(n_rows)[np.ix_(body, body)]

    def allowed_rows(self) -> np.ndarray:
        """Where g_q may be non-zero, shape (rows, n), bool."""
        body = self.body_of_dof()
        out = np.zeros((len(self.rows), body.shape[0]), bool)
        for r, bodies in enumerate(self.rows):
            out[r] = np.isin(body, bodies)
        return out


__all__ = ["BodyCoupling"]
