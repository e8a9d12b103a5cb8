"""A system's parts assembled into a :class:`~nsga_jax.models.Model`.

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

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.linalg import block_diag

from .._custom_types import ConstraintVector, Matrix, Scalar, Vector
from ..models.base import Model
from .base import GROUND, AbstractBody, AbstractConstraint, AbstractContact, AbstractForce, AbstractJoint, Ground


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
        for kind, parts, part_names in self._parts():
            for part, name in zip(parts, part_names):
                for ref in part.bodies:
                    if ref != GROUND and ref not in self.body_names:
                        known = ", ".join(self.body_names) or "none"
                        return f"{kind}.{name}: names body {ref!r}, which does not exist (bodies: {known}, ground)"
                message = part.invalid_on(self._bodies_of(part))
                if message:
                    return f"{kind}.{name}: {message}"
        return None

    def _parts(self):
        return (("joints", self.joints, self.joint_names), ("contacts", self.contacts, self.contact_names),
                ("forces", self.forces, self.force_names))

    def _slices(self) -> dict[str, slice]:
        """Each body's slice of the global coordinates (static)."""
        out, start = {GROUND: slice(0, 0)}, 0
        for body, name in zip(self.bodies, self.body_names):
            out[name] = slice(start, start + body.n_dof)
            start += body.n_dof
        return out

    def _body(self, name: str) -> AbstractBody:
        if name == GROUND:
            return Ground(self.dim)
        return self.bodies[self.body_names.index(name)]

    def _bodies_of(self, part) -> tuple[AbstractBody, ...]:
        return tuple(self._body(name) for name in part.bodies)

    def _gather(self, x: Vector, part) -> tuple[Vector, ...]:
        slices = self._slices()
        return tuple(x[slices[name]] for name in part.bodies)

    @property
    def n_dof(self) -> int:
        return sum(b.n_dof for b in self.bodies)

    @property
    def n_bilateral(self) -> int:
        return sum(b.n_bilateral for b in self.bodies) + sum(j.count(self._bodies_of(j)) for j in self.joints)

    @property
    def n_unilateral(self) -> int:
        return sum(c.count(self._bodies_of(c)) for c in self.contacts)

    @property
    def constant_mass(self) -> bool:
        return all(b.constant_mass for b in self.bodies)

    @property
    def linear_force(self) -> bool:
        return all(b.linear_force for b in self.bodies) and all(f.is_linear(self._bodies_of(f)) for f in self.forces)

    @property
    def velocity_dependent_force(self) -> bool:
        return (any(b.velocity_dependent_force for b in self.bodies)
                or any(f.velocity_dependent and f.depends_on_state(self._bodies_of(f)) for f in self.forces))

    @property
    def linear_constraints(self) -> bool:
        own = all(b.n_bilateral == 0 for b in self.bodies)
        return own and all(c.is_linear(self._bodies_of(c)) for c in (*self.joints, *self.contacts))

    @property
    def bandwidth(self) -> int | None:
        """The widest of the bodies' bands, where every body has one and no
        force couples coordinates (the matrices are then block diagonal)."""
        bands = [b.bandwidth for b in self.bodies]
        if not bands or any(b is None for b in bands):
            return None
        if any(f.depends_on_state(self._bodies_of(f)) for f in self.forces):
            return None
        return max(b for b in bands if b is not None)

    @property
    def mbar(self) -> Scalar:
        """The total mass of the bodies [kg]."""
        return sum((b.total_mass for b in self.bodies[1:]), self.bodies[0].total_mass)

    # --------------------------------------------------------------- physics
    def initial_state(self) -> tuple[Vector, Vector]:
        """``(q0, v0)``, each (n,), from every body's placement and initial velocity."""
        states = [b.initial_state() for b in self.bodies]
        return jnp.concatenate([s[0] for s in states]), jnp.concatenate([s[1] for s in states])

    def _per_body(self, fn, *xs: Vector) -> list:
        slices = self._slices()
        return [fn(b, *(x[slices[name]] for x in xs)) for b, name in zip(self.bodies, self.body_names)]

    def mass(self, q: Vector) -> Matrix:
        return block_diag(*self._per_body(lambda b, qb: b.mass(qb), q))

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        return jnp.concatenate(self._per_body(lambda b, qb, xb: b.mass_product(qb, xb), q, x))

    def force(self, q: Vector, v: Vector, t: Scalar) -> Vector:
        f = jnp.concatenate(self._per_body(lambda b, qb, vb: b.internal_force(qb, vb), q, v))
        slices = self._slices()
        for part in self.forces:
            local = part.generalized(self._bodies_of(part), self._gather(q, part), self._gather(v, part), t)
            for name, fb in zip(part.bodies, local):
                f = f.at[slices[name]].add(fb)
        return f

    def tangents(self, q: Vector, v: Vector, t: Scalar) -> tuple[Matrix, Matrix]:
        pairs = self._per_body(lambda b, qb, vb: b.tangents(qb, vb), q, v)
        K, C = block_diag(*[p[0] for p in pairs]), block_diag(*[p[1] for p in pairs])
        slices = self._slices()
        for part in self.forces:
            bodies = self._bodies_of(part)
            if not part.depends_on_state(bodies):
                continue
            qs, vs = self._gather(q, part), self._gather(v, part)

            def local(qs, vs, part=part, bodies=bodies):
                return part.generalized(bodies, qs, vs, t)

            dq = jax.jacfwd(local, argnums=0)(qs, vs)
            dv = jax.jacfwd(local, argnums=1)(qs, vs) if part.velocity_dependent else None
            for i, row in enumerate(part.bodies):
                for j, col in enumerate(part.bodies):
                    K = K.at[slices[row], slices[col]].add(-dq[i][j])
                    if dv is not None:
                        C = C.at[slices[row], slices[col]].add(-dv[i][j])
        return K, C

    def _constraint_parts(self) -> tuple[AbstractConstraint, ...]:
        return (*self.joints, *self.contacts)

    def bilateral(self, q: Vector) -> ConstraintVector:
        rows = self._per_body(lambda b, qb: b.bilateral(qb), q)
        rows += [j.evaluate(self._bodies_of(j), self._gather(q, j)) for j in self.joints]
        return jnp.concatenate(rows) if rows else jnp.zeros((0,), q.dtype)

    def unilateral(self, q: Vector) -> ConstraintVector:
        rows = [c.evaluate(self._bodies_of(c), self._gather(q, c)) for c in self.contacts]
        return jnp.concatenate(rows) if rows else jnp.zeros((0,), q.dtype)

    @property
    def restitution(self) -> ConstraintVector:
        rows = [c.restitution(self._bodies_of(c)) for c in self.contacts]
        return jnp.concatenate(rows) if rows else jnp.zeros((0,))

    def _row_blocks(self, bilateral_only: bool = False) -> list[tuple[slice, tuple[str, ...], Callable, bool]]:
        """Every block of constraint rows: ``(rows, body names, fn(qs) -> values,
        is_linear)``: the bodies' own constraints, then the joints, then the contacts."""
        blocks: list[tuple[slice, tuple[str, ...], Callable, bool]] = []
        start = 0
        for body, name in zip(self.bodies, self.body_names):
            if body.n_bilateral:
                blocks.append((slice(start, start + body.n_bilateral), (name,),
                               lambda qs, body=body: body.bilateral(qs[0]), False))
                start += body.n_bilateral
        parts = self.joints if bilateral_only else self._constraint_parts()
        for part in parts:
            bodies = self._bodies_of(part)
            count = part.count(bodies)
            evaluate: Callable = lambda qs, part=part, bodies=bodies: part.evaluate(bodies, qs)  # noqa: E731
            blocks.append((slice(start, start + count), part.bodies, evaluate, part.is_linear(bodies)))
            start += count
        return blocks

    def _gather_names(self, x: Vector, names: tuple[str, ...]) -> tuple[Vector, ...]:
        slices = self._slices()
        return tuple(x[slices[name]] for name in names)

    def _scatter_rows(self, rows: int, names: tuple[str, ...], columns, dtype) -> Matrix:
        """A (rows, n) block from per-body column blocks (rows, k_b)."""
        slices = self._slices()
        block = jnp.zeros((rows, self.n_dof), dtype)
        for name, column in zip(names, columns):
            block = block.at[:, slices[name]].add(column)
        return block

    def _jacobian_rows(self, q: Vector, bilateral_only: bool) -> Matrix:
        blocks = [self._scatter_rows(rows.stop - rows.start, names, jax.jacfwd(fn)(self._gather_names(q, names)),
                                     q.dtype)
                  for rows, names, fn, _ in self._row_blocks(bilateral_only)]
        return jnp.concatenate(blocks) if blocks else jnp.zeros((0, self.n_dof), q.dtype)

    def constraint_jacobian(self, q: Vector) -> Matrix:
        """g_q (nc, n), assembled from each part's ``jax.jacfwd`` on its own bodies' coordinates."""
        return self._jacobian_rows(q, bilateral_only=False)

    def bilateral_jacobian(self, q: Vector) -> Matrix:
        """g_q^B (nb, n), part by part."""
        return self._jacobian_rows(q, bilateral_only=True)

    def constraint_curvature(self, q: Vector, mu: ConstraintVector) -> Matrix:
        """d(g_q^T mu)/dq (n, n): each nonlinear part's Hessian of ``mu · g`` on its
        own bodies' coordinates (affine parts add nothing)."""
        n, slices = self.n_dof, self._slices()
        H = jnp.zeros((n, n), q.dtype)
        for rows, names, fn, linear in self._row_blocks():
            if linear:
                continue
            local = jax.hessian(lambda qs, fn=fn, rows=rows: mu[rows] @ fn(qs))(self._gather_names(q, names))
            for i, row in enumerate(names):
                for j, col in enumerate(names):
                    H = H.at[slices[row], slices[col]].add(local[i][j])
        return H

    def velocity_constraint_gradient(self, q: Vector, v: Vector, bilateral_only: bool = False) -> Matrix:
        """G^s = d(g_q v)/dq (nc or nb, n) (eq. 50), part by part (affine parts: zero rows)."""
        blocks = []
        for rows, names, fn, linear in self._row_blocks(bilateral_only):
            count = rows.stop - rows.start
            if linear:
                blocks.append(jnp.zeros((count, self.n_dof), q.dtype))
                continue
            vs = self._gather_names(v, names)

            def rate(qs, fn=fn, vs=vs):
                return jax.jvp(fn, (qs,), (vs,))[1]

            blocks.append(self._scatter_rows(count, names, jax.jacfwd(rate)(self._gather_names(q, names)), q.dtype))
        return jnp.concatenate(blocks) if blocks else jnp.zeros((0, self.n_dof), q.dtype)

    # -------------------------------------------------------------- monitors
    def energy(self, q: Vector, v: Vector) -> Scalar:
        """Kinetic + strain energy of the bodies, plus the potential of every
        conservative force [J]."""
        kinetic = 0.5 * v @ self.mass_product(q, v)
        strain = sum(self._per_body(lambda b, qb: b.strain_energy(qb), q), jnp.zeros((), q.dtype))
        potential = sum((f.potential(self._bodies_of(f), self._gather(q, f)) for f in self.forces),
                        jnp.zeros((), q.dtype))
        return kinetic + strain + potential

    @property
    def has_energy(self) -> bool:
        """Whether every force is conservative (a prescribed load is not)."""
        return all(f.conservative for f in self.forces)

    def angular_speed(self, q: Vector, v: Vector) -> float | None:
        speeds = [s for s in self._per_body(lambda b, qb, vb: b.angular_speed(qb, vb), q, v) if s is not None]
        return float(max(speeds)) if speeds else None

    # ----------------------------------------------------------------- access
    def body(self, name: str) -> AbstractBody:
        """The body called ``name``."""
        return self._body(name)

    def coordinates(self, name: str) -> slice:
        """The slice of the global coordinates that holds body ``name``'s."""
        return self._slices()[name]

    def rows(self, kind: str, name: str) -> slice:
        """The rows of joint or contact ``name`` (``kind`` ``"joints"`` or
        ``"contacts"``) in the constraint vector ``[g^B; g^U]``."""
        start = sum(b.n_bilateral for b in self.bodies)
        for group, names, parts in (("joints", self.joint_names, self.joints),
                                    ("contacts", self.contact_names, self.contacts)):
            for part_name, part in zip(names, parts):
                count = part.count(self._bodies_of(part))
                if group == kind and part_name == name:
                    return slice(start, start + count)
                start += count
        raise KeyError(f"no {kind[:-1]} called {name!r}")
