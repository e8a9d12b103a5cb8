"""The parts a system is assembled from: bodies, and the joints, contacts and
forces that act between them.

Every part is an equinox Module: its numbers are pytree leaves (so a system
can be differentiated and batched in them), its structure (sizes, which body
it acts on, node indices) static fields. A part is a pure function of the
coordinates of the bodies it names; :class:`~nsga_jax._system.model.SystemModel`
gathers those coordinates from the global vector, calls the part, and
scatters the result (and its ``jax.jacfwd`` Jacobian, taken at part level)
back, as :mod:`nsga_jax._assembly` does for elements.

Conventions: a system lives in ``dim`` = 1, 2 or 3 space dimensions (every
body shares it). A point of a body is named by an *anchor*: body-frame
coordinates ``at`` (shape (dim,), metres) on a rigid body or a point mass,
or a node index ``node`` on a flexible body. ``"ground"`` is the fixed frame:
its anchors are world coordinates.
"""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Matrix, Scalar, Vector
from .._validation import Range, check_model_fields

GROUND = "ground"
"""The name of the fixed frame, which every system has (no coordinates)."""


class AbstractPart(eqx.Module):
    """What every part shares: its float fields are checked at construction
    (finite, within ``ranges``, and :meth:`invalid`), as a model's are."""

    ranges: ClassVar[dict[str, Range]] = {}

    def __check_init__(self):
        check_model_fields(self)

    def invalid(self) -> str | None:
        """A rule on concrete values that ``ranges`` cannot state: the broken rule's message, or ``None``."""
        return None


class AbstractBody(AbstractPart):
    """A body: its coordinates, mass, internal forces and material points.

    Class attributes state the body's structure, from which the system's is
    derived: ``constant_mass`` (M does not depend on q), ``linear_force`` (the
    internal force is affine in q and v), ``velocity_dependent_force``,
    ``linear_points`` (every material point's position is affine in q, so
    a constraint that is affine in positions is affine in q).
    """

    constant_mass: ClassVar[bool] = True
    linear_force: ClassVar[bool] = True
    velocity_dependent_force: ClassVar[bool] = False
    linear_points: ClassVar[bool] = True
    linear_angle: ClassVar[bool] = True
    """Where the body has a planar orientation, whether it is affine in q (a coordinate)."""
    has_nodes: ClassVar[bool] = False
    """Flexible bodies name their points by node index, the others by body-frame coordinates."""

    @property
    @abc.abstractmethod
    def dim(self) -> int:
        """The space dimension the body lives in (1, 2 or 3)."""

    @property
    @abc.abstractmethod
    def n_dof(self) -> int:
        """Number of the body's coordinates k."""

    @property
    def n_bilateral(self) -> int:
        """Number of the body's own bilateral constraints (rigidity of natural coordinates)."""
        return 0

    @property
    def bandwidth(self) -> int | None:
        """Half-bandwidth of the body's M, K and C, where they are banded."""
        return None

    @property
    @abc.abstractmethod
    def total_mass(self) -> Scalar:
        """The body's mass [kg] (its share of the characteristic mass m̄)."""

    @property
    def n_nodes(self) -> int:
        """Number of nodes of a flexible body (0 for a rigid one)."""
        return 0

    @abc.abstractmethod
    def initial_state(self) -> tuple[Vector, Vector]:
        """``(q0, v0)``, each (k,), from the body's placement and initial velocity."""

    @abc.abstractmethod
    def mass(self, q: Vector) -> Matrix:
        """M(q), shape (k, k)."""

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        """M(q) @ x, shape (k,)."""
        return self.mass(q) @ x

    def internal_force(self, q: Vector, v: Vector) -> Vector:
        """Elastic and damping forces (k,) [N]; zero for a rigid body."""
        return jnp.zeros_like(q)

    def tangents(self, q: Vector, v: Vector) -> tuple[Matrix, Matrix]:
        """K = -d(internal force)/dq and C = -d/dv, each (k, k)."""
        K = -jax.jacfwd(self.internal_force, argnums=0)(q, v)
        C = -jax.jacfwd(self.internal_force, argnums=1)(q, v) if self.velocity_dependent_force else jnp.zeros_like(K)
        return K, C

    def kinetic_energy(self, q: Vector, v: Vector) -> Scalar:
        """½ vᵀ M(q) v [J]."""
        return 0.5 * v @ self.mass_product(q, v)

    def strain_energy(self, q: Vector) -> Scalar:
        """Elastic energy [J]; zero for a rigid body."""
        return jnp.zeros((), q.dtype)

    @abc.abstractmethod
    def gravity_force(self, g: Vector) -> Vector:
        """The generalised force (k,) [N] of the uniform acceleration ``g`` (dim,)
        [m/s²] on the body's mass; constant, and its potential is ``-gravity_force(g) @ q``."""

    def bilateral(self, q: Vector) -> Vector:
        """The body's own bilateral constraints, shape (n_bilateral,) [m]."""
        return jnp.zeros((0,), q.dtype)

    @abc.abstractmethod
    def position(self, q: Vector, at: Vector, node: int | None) -> Vector:
        """World position (dim,) [m] of the material point named by ``at`` (body
        frame, (dim,)) or ``node`` (a flexible body's node index)."""

    def angle(self, q: Vector, node: int | None) -> Scalar:
        """Planar orientation [rad] of the body (or of a beam node's cross-section)."""
        raise NotImplementedError(f"{type(self).__name__} has no planar orientation")

    @property
    def has_angle(self) -> bool:
        """Whether :meth:`angle` is defined (planar rigid bodies and beams)."""
        return type(self).angle is not AbstractBody.angle

    def angular_speed(self, q: Vector, v: Vector) -> Scalar | None:
        """Largest angular speed [rad/s] of the body, where it turns."""
        return None

    def invalid_anchor(self, at, node) -> str | None:
        """Why ``at``/``node`` names no material point of this body, or ``None``."""
        if self.has_nodes:
            if node is None:
                return "a flexible body's points are named by node index (node = ...), not body coordinates"
            if not -self.n_nodes <= node < self.n_nodes:
                return f"node {node} does not exist: the body has nodes 0 ... {self.n_nodes - 1} (or -1 for the last)"
            return None
        if node is not None:
            return "a rigid body's points are named by body-frame coordinates (at = [...]), not by node"
        if jnp.shape(at) not in ((self.dim,), (0,)):
            return (f"the body lives in {self.dim} dimensions: at must have {self.dim} coordinates, "
                    f"got shape {jnp.shape(at)}")
        return None


class Ground(AbstractBody):
    """The fixed frame: no coordinates; its anchors are world coordinates."""

    space_dim: int = eqx.field(static=True)

    @property
    def dim(self) -> int:
        return self.space_dim

    @property
    def n_dof(self) -> int:
        return 0

    @property
    def total_mass(self) -> Scalar:
        return jnp.zeros(())

    def initial_state(self) -> tuple[Vector, Vector]:
        return jnp.zeros((0,)), jnp.zeros((0,))

    def mass(self, q: Vector) -> Matrix:
        return jnp.zeros((0, 0), q.dtype)

    def gravity_force(self, g: Vector) -> Vector:
        return jnp.zeros((0,), g.dtype)

    def position(self, q: Vector, at: Vector, node: int | None) -> Vector:
        return at.astype(q.dtype)

    def angle(self, q: Vector, node: int | None) -> Scalar:
        return jnp.zeros((), q.dtype)


class AbstractConstraint(AbstractPart):
    """A joint (bilateral) or a contact (unilateral): :meth:`count` scalar
    constraints [m] on the coordinates of the bodies it names (``bodies``, static)."""

    @property
    @abc.abstractmethod
    def bodies(self) -> tuple[str, ...]:
        """Names of the bodies the constraint acts on (``"ground"`` included where it is one)."""

    @abc.abstractmethod
    def count(self, bodies: tuple[AbstractBody, ...]) -> int:
        """Number of scalar constraints on these bodies (static)."""

    @abc.abstractmethod
    def evaluate(self, bodies: tuple[AbstractBody, ...], qs: tuple[Vector, ...]) -> Vector:
        """The constraints (count,) [m], from the named bodies and their coordinates."""

    @abc.abstractmethod
    def is_linear(self, bodies: tuple[AbstractBody, ...]) -> bool:
        """Whether the constraint is affine in the coordinates of these bodies."""

    def invalid_on(self, bodies: tuple[AbstractBody, ...]) -> str | None:
        """Why the constraint cannot act on these bodies (wrong anchors, dimensions), or ``None``."""
        return None

    def angular_speed(self, bodies: tuple[AbstractBody, ...], qs: tuple[Vector, ...],
                      vs: tuple[Vector, ...]) -> Scalar | None:
        """Angular speed [rad/s] of what the constraint makes turn (a rod), for
        the coarse-step warning; ``None`` where nothing turns."""
        return None


class AbstractJoint(AbstractConstraint):
    """A bilateral constraint: g(q) = 0."""


class AbstractContact(AbstractConstraint):
    """Unilateral constraints g(q) >= 0 with Newton restitution, and Coulomb
    friction where the contact has a coefficient ``mu`` (a field that is
    ``None`` on a frictionless contact: the friction rows then do not exist)."""

    @abc.abstractmethod
    def restitution(self, bodies: tuple[AbstractBody, ...]) -> Vector:
        """Restitution coefficient of each gap, shape (count,), in [0, 1]."""

    @property
    def frictional(self) -> bool:
        """Whether the contact carries Coulomb friction (static: a coefficient was given)."""
        return getattr(self, "mu", None) is not None

    def friction(self, bodies: tuple[AbstractBody, ...]) -> Vector:
        """The Coulomb coefficient μ of each gap, shape (count,)."""
        return jnp.broadcast_to(getattr(self, "mu"), (self.count(bodies),))

    def slip_velocity(self, bodies: tuple[AbstractBody, ...], qs: tuple[Vector, ...],
                      vs: tuple[Vector, ...]) -> Vector:
        """Tangential velocity of each contact point, shape (count, dim - 1)
        [m/s]: the relative velocity of the touching material points on the
        contact's tangents (linear in the velocities ``vs``)."""
        raise NotImplementedError(f"{type(self).__name__} has no friction")


class AbstractForce(AbstractPart):
    """An applied force: generalised forces on the bodies it names."""

    velocity_dependent: ClassVar[bool] = False
    conservative: ClassVar[bool] = True
    """Whether :meth:`potential` is the force's potential (time-dependent loads are not)."""

    @property
    @abc.abstractmethod
    def bodies(self) -> tuple[str, ...]:
        """Names of the bodies the force acts on."""

    @abc.abstractmethod
    def generalized(self, bodies: tuple[AbstractBody, ...], qs: tuple[Vector, ...], vs: tuple[Vector, ...],
                    t: Scalar) -> tuple[Vector, ...]:
        """The generalised force on each named body (each (k_b,)) [N]."""

    @abc.abstractmethod
    def is_linear(self, bodies: tuple[AbstractBody, ...]) -> bool:
        """Whether the force is affine in (q, v) (constant tangents)."""

    def depends_on_state(self, bodies: tuple[AbstractBody, ...]) -> bool:
        """``False`` when the force depends on time only (gravity, a load at a
        point that moves linearly with q): it adds nothing to the tangents."""
        return True

    def potential(self, bodies: tuple[AbstractBody, ...], qs: tuple[Vector, ...]) -> Scalar:
        """Potential energy [J] of a conservative force."""
        return jnp.zeros(())

    def invalid_on(self, bodies: tuple[AbstractBody, ...]) -> str | None:
        """Why the force cannot act on these bodies, or ``None``."""
        return None


def anchor(at) -> Vector:
    """An anchor's body-frame coordinates as a float array; ``None`` (the body's
    origin: a rigid body's centre of mass, the ground's origin) is the empty
    array, which :func:`point` reads as zeros."""
    return jnp.zeros((0,)) if at is None else jnp.asarray(at, dtype=float)


def point(body: AbstractBody, q: Vector, at: Vector, node: int | None) -> Vector:
    """World position (dim,) [m] of an anchor of ``body`` (an empty ``at``: the origin)."""
    if not body.has_nodes and at.shape[-1] == 0:
        at = jnp.zeros((body.dim,), q.dtype)
    return body.position(q, at, node)


def point_force(body: AbstractBody, q: Vector, at: Vector, node: int | None, force: Vector) -> Vector:
    """The generalised force (k,) of a force ``force`` (dim,) [N] applied at a
    material point: ``(dx/dq)^T F`` by a vector–Jacobian product."""
    _, pullback = jax.vjp(lambda x: point(body, x, at, node), q)
    return pullback(force)[0]
