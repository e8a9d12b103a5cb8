"""The capabilities a model may have, beyond what every model needs.

:class:`~nsga_jax._models.Model` states what every model gives the
integrator (sizes, M, f, its tangents, the constraints and their structure
flags). Each class here is one capability a model may add, with defaults
that mean "not this": a model overrides the members of the capabilities it
has, and :func:`~nsga_jax._models.check.check_model` checks each capability
the model declares against its own functions
(:data:`~nsga_jax._models.check.CAPABILITIES`). Which path a run takes is
decided at trace time from these declarations (static Python values):

- :class:`FrictionalContacts`: Coulomb friction at some unilateral
  contacts (``n_friction > 0``);
- :class:`ElementBlocks`: M and K as element blocks and the constraint rows
  node by node, for the matrix-free path (``matrix_free``);
- :class:`EnergyMonitor`: a total mechanical energy the runs monitor
  (``has_energy``) and the bodies' angular speed for the coarse-step warning.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jax import lax

from .._blocks import ElementMatrix, KroneckerMass, NodeRows
from .._custom_types import ConstraintMatrix, ConstraintVector, Scalar, Vector


class FrictionalContacts(eqx.Module):
    """Coulomb friction at ``n_friction`` of the unilateral contacts
    (docs/friction.md); the defaults: no frictional contact."""

    @property
    def n_friction(self) -> int:
        """Number of frictional contacts ``nf`` (unilateral constraints with a
        Coulomb friction coefficient); 0: every contact is frictionless and no
        friction row is ever formed."""
        return 0

    @property
    def friction_dim(self) -> int:
        """Tangent directions per frictional contact: 1 in a planar system (a
        friction segment), 2 in space (a friction disk); 0 without friction."""
        return 0

    @property
    def friction_normals(self) -> tuple[int, ...]:
        """For each frictional contact, the row of its normal gap in the
        constraint vector ``[g^B; g^U]`` (static, nf entries)."""
        return ()

    @property
    def friction_coefficients(self) -> ConstraintVector:
        """Coulomb coefficients μ >= 0 of the frictional contacts, shape (nf,)."""
        return lax.full((self.n_friction,), 0.0)

    def tangent_jacobian(self, q: Vector) -> ConstraintMatrix:
        """g_T: the map from v to the tangential (slip) velocities of the
        frictional contacts, shape (nf * friction_dim, n), contact by contact
        (rows ``j * friction_dim + d``: tangent d of contact j) [m/s per unit of v]."""
        return jnp.zeros((0, q.shape[0]), q.dtype)


class ElementBlocks(eqx.Module):
    """The matrix-free path's view of a large model (:mod:`~nsga_jax._integrators.krylov`);
    the defaults: not matrix-free."""

    @property
    def matrix_free(self) -> bool:
        """``True`` when the model gives its iteration matrices as element
        blocks (:meth:`element_mass`, :meth:`element_stiffness`) and its constraint rows node by node
        (:meth:`constraint_rows`), so that a large model is solved without
        forming any n × n or (nc, n) array (:mod:`~nsga_jax._integrators.krylov`).
        Such a model has a constant mass, a force that does not depend on v,
        affine constraints, and orthonormal rows: no two share a
        coordinate, except a node's rows along its coordinate axes (a pinned
        node's bilaterals, which come first)."""
        return False

    def element_mass(self, q: Vector) -> ElementMatrix:
        """M(q) as element blocks, never assembled (matrix-free models)."""
        raise NotImplementedError(f"{type(self).__name__} is not matrix-free")

    def element_stiffness(self, q: Vector) -> ElementMatrix:
        """K(q) = -df/dq as element blocks, never assembled (matrix-free models)."""
        raise NotImplementedError(f"{type(self).__name__} is not matrix-free")

    def kronecker_mass(self) -> KroneckerMass | None:
        """M as a Kronecker product, whose product and exact inverse cost O(n)
        (a matrix-free model with a constant, structured mass): the inverse
        preconditions its iteration matrices. ``None`` where M has no such form."""
        return None

    def constraint_rows(self, q: Vector) -> NodeRows:
        """g_q(q) as node-local rows (matrix-free models), shape (nc, n)."""
        raise NotImplementedError(f"{type(self).__name__} is not matrix-free")


class EnergyMonitor(eqx.Module):
    """What the runs monitor where a model defines it; the defaults: nothing."""

    def energy(self, q: Vector, v: Vector) -> Scalar:
        """Total mechanical energy [J] (kinetic + potential + strain), where the
        model defines one: runs then monitor it (largest rise, rise at impacts)."""
        raise NotImplementedError

    @property
    def has_energy(self) -> bool:
        """Whether the model defines :meth:`energy`."""
        return type(self).energy is not EnergyMonitor.energy

    def angular_speed(self, q: Vector, v: Vector) -> float | None:
        """The largest angular speed [rad/s] of the model's bodies at (q, v), for
        the coarse-step warning before a run; ``None`` where nothing turns."""
        return None


__all__ = ["ElementBlocks", "EnergyMonitor", "FrictionalContacts"]
