"""A system's parts assembled into a :class:`~nsga_jax._models.Model`.

The global coordinates are the bodies' coordinates one after the other, in
the order the bodies were added. Every part is evaluated on the coordinates
of the bodies it names (gathered by static slices), and its contribution is
scattered back: forces into the force vector, part-level ``jax.jacfwd``
Jacobians into K, C and g_q. The constraints are ``[bodies' own bilateral
constraints; joints; contacts]``, each part's rows in the order it was added.

The model's structure (constant mass, linear force, velocity-dependent
force, linear constraints, bandwidth) is derived from its parts' own
structure, never declared by hand; :func:`nsga_jax.check_model` checks it
against the functions, as for any model.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import ConstraintVector, Matrix, Scalar, Vector
from .._models.base import Model
from .._results import ConfigError
from . import assemble, layout
from . import matrix_free as large
from .base import AbstractBody, AbstractContact, AbstractForce, AbstractJoint
from .forces import Gravity
from .groups import call, gather, scatter_block, scatter_vector


class SystemModel(Model):
    """Bodies, joints, contacts and forces, with their names (static).

    Build it with :class:`~nsga_jax.system.System` (which checks names and
    references); the model itself is a pure pytree of its parts.
    """

    bodies: tuple[AbstractBody, ...]
    joints: tuple[AbstractJoint, ...]
    contacts: tuple[AbstractContact, ...]
    forces: tuple[AbstractForce, ...]
    body_names: tuple[str, ...] = eqx.field(static=True)
    joint_names: tuple[str, ...] = eqx.field(static=True)
    contact_names: tuple[str, ...] = eqx.field(static=True)
    force_names: tuple[str, ...] = eqx.field(static=True)
    dim: int = eqx.field(static=True)

    # ------------------------------------------------------------- structure
    def __check_init__(self):  # references are structure: checked where values are traced (invalid() is not)
        if message := layout.reference_rule(self):
            raise ConfigError(f"{type(self).__name__}.{message}")

    def invalid(self) -> str | None:
        names: dict[str, set[str]] = {}
        for kind, group in (("bodies", self.body_names), ("joints", self.joint_names),
                            ("contacts", self.contact_names), ("forces", self.force_names)):
            for name in group:
                if name in names.get(kind, set()):
                    return f"{kind}.{name}: the name is used twice"
                names.setdefault(kind, set()).add(name)
        for body, name in zip(self.bodies, self.body_names):
            if body.dim != self.dim:
                return f"bodies.{name}: lives in {body.dim} dimensions, the system in {self.dim}"
        for kind, parts, part_names in layout.named_parts(self):
            for part, name in zip(parts, part_names):
                message = part.invalid_on(layout.bodies_of(self, part))
                if message:
                    return f"{kind}.{name}: {message}"
        return None

    @property
    def n_dof(self) -> int:
        return sum(b.n_dof for b in self.bodies)

    @property
    def n_own_bilateral(self) -> int:
        """Rows of the bodies' own bilateral constraints (the first rows of g^B)."""
        return sum(b.n_bilateral for b in self.bodies)

    @property
    def n_bilateral(self) -> int:
        return self.n_own_bilateral + sum(j.count(layout.bodies_of(self, j)) for j in self.joints)

    @property
    def n_unilateral(self) -> int:
        return sum(c.count(layout.bodies_of(self, c)) for c in self.contacts)

    @property
    def constant_mass(self) -> bool:
        return all(b.constant_mass for b in self.bodies)

    @property
    def linear_force(self) -> bool:
        return (all(b.linear_force for b in self.bodies)
                and all(f.is_linear(layout.bodies_of(self, f)) for f in self.forces))

    @property
    def velocity_dependent_force(self) -> bool:
        return (any(b.velocity_dependent_force for b in self.bodies)
                or any(f.velocity_dependent and f.depends_on_state(layout.bodies_of(self, f)) for f in self.forces))

    @property
    def linear_constraints(self) -> bool:
        own = all(b.n_bilateral == 0 for b in self.bodies)
        return own and all(c.is_linear(layout.bodies_of(self, c)) for c in (*self.joints, *self.contacts))

    @property
    def bandwidth(self) -> int | None:
        """The widest of the bodies' bands, where every body has one and no
        force couples coordinates (the matrices are then block diagonal)."""
        bands = [b.bandwidth for b in self.bodies]
        if not bands or any(b is None for b in bands):
            return None
        if any(f.depends_on_state(layout.bodies_of(self, f)) for f in self.forces):
            return None
        return max(b for b in bands if b is not None)

    # each body's coordinates, each row's bodies, the bodies a force couples (_integrators/structured.py)
    body_coupling = property(layout.body_coupling)  # type: ignore[assignment]
    # a large model solved without assembling (_system/matrix_free.py)
    matrix_free = property(large.is_matrix_free)  # type: ignore[assignment]
    element_mass = large.element_mass
    element_stiffness = large.element_stiffness
    kronecker_mass = large.kronecker_mass  # type: ignore[assignment]
    constraint_rows = large.constraint_rows

    @property
    def mbar(self) -> Scalar:
        """The total mass of the bodies [kg]."""
        return sum((b.total_mass for b in self.bodies[1:]), self.bodies[0].total_mass)

    # ----------------------------------------------------------- grouping
    # --------------------------------------------------------------- physics
    def initial_state(self) -> tuple[Vector, Vector]:
        """``(q0, v0)``, each (n,), from every body's placement and initial velocity."""
        states = [b.initial_state() for b in self.bodies]
        return jnp.concatenate([s[0] for s in states]), jnp.concatenate([s[1] for s in states])

    def mass(self, q: Vector) -> Matrix:
        return assemble.body_matrix(self, lambda b, qb: b.mass(qb), q)

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        return assemble.body_vector(self, lambda b, qb, xb: b.mass_product(qb, xb), q, x)

    def force(self, q: Vector, v: Vector, t: Scalar) -> Vector:
        f = assemble.body_vector(self, lambda b, qb, vb: b.internal_force(qb, vb), q, v)
        for parts in assemble.force_parts(self):
            if isinstance(parts, Gravity):
                f = f + assemble.gravity_vector(self, parts, q.dtype)
                continue
            group, stacked, bodies, _ = parts

            def local(part, bodies, qs, vs):
                return part.generalized(bodies, qs, vs, t)

            values = call(group, local, stacked, bodies, *layout.slot_coordinates(self, group, q, v))
            for cols, value in zip(group.columns, values):
                f = scatter_vector(f, cols, value)
        return f

    def tangents(self, q: Vector, v: Vector, t: Scalar) -> tuple[Matrix, Matrix]:
        K = assemble.body_matrix(self, lambda b, qb, vb: b.tangents(qb, vb)[0], q, v)
        C = assemble.body_matrix(self, lambda b, qb, vb: b.tangents(qb, vb)[1], q, v)
        for parts in assemble.force_parts(self):
            if isinstance(parts, Gravity):
                continue
            group, stacked, bodies, member = parts
            if not member.depends_on_state(layout.bodies_of(self, member)):
                continue

            def local(part, bodies, qs, vs):
                return part.generalized(bodies, qs, vs, t)

            qs, vs = layout.slot_coordinates(self, group, q, v)
            dq = call(group, jax.jacfwd(local, argnums=2), stacked, bodies, qs, vs)
            dv = call(group, jax.jacfwd(local, argnums=3), stacked, bodies, qs, vs) if member.velocity_dependent \
                else None
            for i, rows in enumerate(group.columns):
                for j, cols in enumerate(group.columns):
                    K = scatter_block(K, rows, cols, -dq[i][j])
                    if dv is not None:
                        C = scatter_block(C, rows, cols, -dv[i][j])
        return K, C

    def bilateral(self, q: Vector) -> ConstraintVector:
        return assemble.constraint_vector(self, q, "bilateral")

    def unilateral(self, q: Vector) -> ConstraintVector:
        return assemble.constraint_vector(self, q, "unilateral")

    def constraints(self, q: Vector) -> ConstraintVector:
        return assemble.constraint_vector(self, q, "all")

    @property
    def restitution(self) -> ConstraintVector:
        rows = [c.restitution(layout.bodies_of(self, c)) for c in self.contacts]
        return jnp.concatenate(rows) if rows else jnp.zeros((0,))

    # -------------------------------------------------------------- friction
    @property
    def n_friction(self) -> int:
        return sum(c.count(layout.bodies_of(self, c)) for c in self.contacts if c.frictional)

    @property
    def friction_dim(self) -> int:
        return self.dim - 1 if self.n_friction else 0

    @property
    def friction_normals(self) -> tuple[int, ...]:
        rows: list[int] = []
        for contact, name in zip(self.contacts, self.contact_names):
            if contact.frictional:
                span = self.rows("contacts", name)
                rows.extend(range(span.start, span.stop))
        return tuple(rows)

    @property
    def friction_coefficients(self) -> ConstraintVector:
        rows = [c.friction(layout.bodies_of(self, c)) for c in self.contacts if c.frictional]
        return jnp.concatenate(rows) if rows else jnp.zeros((0,))

    def tangent_jacobian(self, q: Vector) -> Matrix:
        """g_T (nf * friction_dim, n): each frictional contact's part-level
        ``jax.jacfwd`` of its slip velocity in the velocities of its bodies."""
        nf, dt = self.n_friction, self.friction_dim
        frictional = tuple(c for c in self.contacts if c.frictional)
        G = jnp.zeros((nf, dt, self.n_dof), q.dtype)
        for group, stacked, bodies, _ in layout.part_groups(self, frictional, first_row=0):
            def slip(part, bodies, qs, vs):
                return part.slip_velocity(bodies, qs, vs)

            qs, vs = layout.slot_coordinates(self, group, q, jnp.zeros_like(q))
            blocks = call(group, jax.jacfwd(slip, argnums=3), stacked, bodies, qs, vs)  # per slot (.., k, dt, kb)
            for cols, block in zip(group.columns, blocks):
                for d in range(dt):
                    G = G.at[:, d].set(scatter_block(G[:, d], group.rows, cols, block[..., d, :]))
        return G.reshape(nf * dt, self.n_dof)

    def constraint_jacobian(self, q: Vector) -> Matrix:
        """g_q (nc, n), assembled from each part's ``jax.jacfwd`` on its own bodies' coordinates."""
        return assemble.jacobian_rows(self, q, bilateral_only=False)

    def bilateral_jacobian(self, q: Vector) -> Matrix:
        """g_q^B (nb, n), part by part."""
        return assemble.jacobian_rows(self, q, bilateral_only=True)

    def constraint_curvature(self, q: Vector, mu: ConstraintVector) -> Matrix:
        """d(g_q^T mu)/dq (n, n): each nonlinear part's Hessian of ``mu · g`` on its
        own bodies' coordinates (affine parts add nothing)."""
        H = jnp.zeros((self.n_dof, self.n_dof), q.dtype)
        for group, module, bodies, fn, linear in layout.row_groups(self):
            if linear:
                continue

            def weighted(module, bodies, qs, weights, fn=fn):
                return weights @ fn(module, bodies, qs)

            (qs,) = layout.slot_coordinates(self, group, q)
            local = call(group, jax.hessian(weighted, argnums=2), module, bodies, qs, mu[group.rows])
            for i, rows in enumerate(group.columns):
                for j, cols in enumerate(group.columns):
                    H = scatter_block(H, rows, cols, local[i][j])
        return H

    def velocity_constraint_gradient(self, q: Vector, v: Vector, bilateral_only: bool = False) -> Matrix:
        """G^s = d(g_q v)/dq (nc or nb, n) (eq. 50), part by part (affine parts: zero rows)."""
        rows = self.n_bilateral if bilateral_only else self.n_constraints
        out = jnp.zeros((rows, self.n_dof), q.dtype)
        for group, module, bodies, fn, linear in layout.row_groups(self, "bilateral" if bilateral_only else "all"):
            if linear:
                continue

            def rate(module, bodies, qs, vs, fn=fn):
                return jax.jvp(lambda x: fn(module, bodies, x), (qs,), (vs,))[1]

            qs, vs = layout.slot_coordinates(self, group, q, v)
            blocks = call(group, jax.jacfwd(rate, argnums=2), module, bodies, qs, vs)
            for cols, block in zip(group.columns, blocks):
                out = scatter_block(out, group.rows, cols, block)
        return out

    # -------------------------------------------------------------- monitors
    def energy(self, q: Vector, v: Vector) -> Scalar:
        """Kinetic + strain energy of the bodies, plus the potential of every
        conservative force [J] (gravity's ``-f_g · q``)."""
        energy = jnp.zeros((), q.dtype)
        for group, stacked in layout.body_groups(self):  # an element body's element by element, never assembled
            (cols,) = group.columns
            energy = energy + jnp.sum(call(group, lambda b, qb, vb: b.kinetic_energy(qb, vb) + b.strain_energy(qb),
                                           stacked, gather(q, cols), gather(v, cols)))
        for parts in assemble.force_parts(self):
            if isinstance(parts, Gravity):
                energy = energy - assemble.gravity_vector(self, parts, q.dtype) @ q
                continue
            group, stacked, bodies, _ = parts
            (qs,) = layout.slot_coordinates(self, group, q)
            energy = energy + jnp.sum(call(group, lambda p, bodies, qs: p.potential(bodies, qs), stacked, bodies, qs))
        return energy

    @property
    def has_energy(self) -> bool:
        """Whether every force is conservative (a prescribed load is not)."""
        return all(f.conservative for f in self.forces)

    def angular_speed(self, q: Vector, v: Vector) -> float | None:
        slices = layout.body_slices(self)
        speeds = [s for b, name in zip(self.bodies, self.body_names)
                  if (s := b.angular_speed(q[slices[name]], v[slices[name]])) is not None]
        speeds += [s for j in self.joints  # a rod's rate, where a joint makes something turn
                   if (s := j.angular_speed(layout.bodies_of(self, j), tuple(q[slices[n]] for n in j.bodies),
                                            tuple(v[slices[n]] for n in j.bodies))) is not None]
        return float(max(speeds)) if speeds else None

    # ----------------------------------------------------------------- access
    def body(self, name: str) -> AbstractBody:
        """The body called ``name``."""
        return layout.body(self, name)

    def coordinates(self, name: str) -> slice:
        """The slice of the global coordinates that holds body ``name``'s."""
        return layout.body_slices(self)[name]

    def rows(self, kind: str, name: str) -> slice:
        """The rows of joint or contact ``name`` (``kind`` ``"joints"`` or
        ``"contacts"``) in the constraint vector ``[g^B; g^U]``."""
        start = sum(b.n_bilateral for b in self.bodies)
        for group, names, parts in (("joints", self.joint_names, self.joints),
                                    ("contacts", self.contact_names, self.contacts)):
            for part_name, part in zip(names, parts):
                count = part.count(layout.bodies_of(self, part))
                if group == kind and part_name == name:
                    return slice(start, start + count)
                start += count
        raise KeyError(f"no {kind[:-1]} called {name!r}")
