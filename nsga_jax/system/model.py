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
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import ConstraintVector, Matrix, Scalar, Vector
from ..models.base import Model
from .base import GROUND, AbstractBody, AbstractConstraint, AbstractContact, AbstractForce, AbstractJoint, Ground
from .forces import Gravity
from .groups import Group, call, columns_of, gather, group_by_kind, kind_of, scatter_block, scatter_vector, shift, stack


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
    def n_own_bilateral(self) -> int:
        """Rows of the bodies' own bilateral constraints (the first rows of g^B)."""
        return sum(b.n_bilateral for b in self.bodies)

    @property
    def n_bilateral(self) -> int:
        return self.n_own_bilateral + sum(j.count(self._bodies_of(j)) for j in self.joints)

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

    # ----------------------------------------------------------- grouping
    def _body_groups(self, names: tuple[str, ...] | None = None) -> list[tuple[Group, Any]]:
        """The bodies (those named, default all) in groups of one kind, each
        with its stacked bodies (the body itself for a group of one)."""
        slices = self._slices()
        chosen = [i for i, name in enumerate(self.body_names) if names is None or name in names]
        out = []
        for members in group_by_kind([kind_of(self.bodies[i]) for i in chosen]):
            idx = tuple(chosen[m] for m in members)
            group = Group(idx, (columns_of([slices[self.body_names[i]] for i in idx]),))
            out.append((group, self._stacked([self.bodies[i] for i in idx])))
        return out

    @staticmethod
    def _stacked(modules: list) -> Any:
        return modules[0] if len(modules) == 1 else stack(modules)

    def _part_groups(self, parts: tuple, first_row: int | None = None) -> list[tuple[Group, Any, tuple, Any]]:
        """Parts in groups of one kind acting on bodies of one kind each: the
        group (with each member's rows from ``first_row`` on, for constraints),
        the stacked parts, the stacked bodies of each slot, and the first
        member (whose static answers stand for the group's)."""
        slices = self._slices()
        starts, row = [], first_row or 0
        for part in parts:
            starts.append(row)
            if first_row is not None:
                row += part.count(self._bodies_of(part))
        keys = [(kind_of(p), tuple(kind_of(b) for b in self._bodies_of(p))) for p in parts]
        out = []
        for members in group_by_kind(keys):
            chosen = [parts[m] for m in members]
            columns = tuple(columns_of([slices[p.bodies[s]] for p in chosen]) for s in range(len(chosen[0].bodies)))
            rows = None
            if first_row is not None:
                count = chosen[0].count(self._bodies_of(chosen[0]))
                rows = (slice(starts[members[0]], starts[members[0]] + count) if len(members) == 1 else
                        np.stack([np.arange(starts[m], starts[m] + count) for m in members]).astype(np.int32))
            bodies = tuple(self._stacked([self._bodies_of(p)[s] for p in chosen]) for s in range(len(columns)))
            out.append((Group(tuple(members), columns, rows), self._stacked(chosen), bodies, chosen[0]))
        return out

    def _row_groups(self, which: str = "all") -> list[tuple[Group, Any, tuple, Callable, bool]]:
        """The groups of constraint rows (rows of ``[g^B; g^U]``) of ``which``
        constraints (``"bilateral"``, ``"unilateral"`` or ``"all"``):
        ``(group, module, slot bodies, fn(module, bodies, qs) -> rows,
        is_linear)``; the bodies' own constraints first, then the joints,
        then the contacts."""
        out: list[tuple[Group, Any, tuple, Callable, bool]] = []
        if which != "unilateral":
            starts = np.cumsum([0] + [b.n_bilateral for b in self.bodies])
            own = tuple(name for b, name in zip(self.bodies, self.body_names) if b.n_bilateral)
            for group, stacked in self._body_groups(own):
                count = self.bodies[group.members[0]].n_bilateral
                first = [int(starts[m]) for m in group.members]
                rows = (slice(first[0], first[0] + count) if group.single else
                        np.stack([np.arange(f, f + count) for f in first]).astype(np.int32))
                out.append((group._replace(rows=rows), stacked, (stacked,),
                            lambda body, bodies, qs: body.bilateral(qs[0]), False))
        sections: list[tuple[tuple, int]] = []
        if which != "unilateral":
            sections.append((self.joints, self.n_own_bilateral))
        if which != "bilateral":
            sections.append((self.contacts, self.n_bilateral))
        for parts, first_row in sections:
            for group, stacked, bodies, first in self._part_groups(parts, first_row):
                out.append((group, stacked, bodies, lambda part, bodies, qs: part.evaluate(bodies, qs),
                            first.is_linear(self._bodies_of(first))))
        return out

    # --------------------------------------------------------------- physics
    def initial_state(self) -> tuple[Vector, Vector]:
        """``(q0, v0)``, each (n,), from every body's placement and initial velocity."""
        states = [b.initial_state() for b in self.bodies]
        return jnp.concatenate([s[0] for s in states]), jnp.concatenate([s[1] for s in states])

    def _body_vector(self, fn: Callable, *xs: Vector) -> Vector:
        """Per-body vectors (k,) from ``fn(body, *local xs)``, assembled (n,)."""
        if len(self.bodies) == 1:
            return fn(self.bodies[0], *xs)
        out = jnp.zeros((self.n_dof,), xs[0].dtype)
        for group, stacked in self._body_groups():
            (cols,) = group.columns
            out = scatter_vector(out, cols, call(group, fn, stacked, *(gather(x, cols) for x in xs)))
        return out

    def _body_matrix(self, fn: Callable, *xs: Vector) -> Matrix:
        """Per-body matrices (k, k) from ``fn(body, *local xs)``, assembled block diagonal (n, n)."""
        if len(self.bodies) == 1:
            return fn(self.bodies[0], *xs)
        out = jnp.zeros((self.n_dof, self.n_dof), xs[0].dtype)
        for group, stacked in self._body_groups():
            (cols,) = group.columns
            out = scatter_block(out, cols, cols, call(group, fn, stacked, *(gather(x, cols) for x in xs)))
        return out

    def mass(self, q: Vector) -> Matrix:
        return self._body_matrix(lambda b, qb: b.mass(qb), q)

    def mass_product(self, q: Vector, x: Vector) -> Vector:
        return self._body_vector(lambda b, qb, xb: b.mass_product(qb, xb), q, x)

    def force(self, q: Vector, v: Vector, t: Scalar) -> Vector:
        f = self._body_vector(lambda b, qb, vb: b.internal_force(qb, vb), q, v)
        for parts in self._force_parts():
            if isinstance(parts, Gravity):
                f = f + self._gravity_vector(parts, q.dtype)
                continue
            group, stacked, bodies, _ = parts

            def local(part, bodies, qs, vs):
                return part.generalized(bodies, qs, vs, t)

            values = call(group, local, stacked, bodies, *self._slot_coordinates(group, q, v))
            for cols, value in zip(group.columns, values):
                f = scatter_vector(f, cols, value)
        return f

    def _force_parts(self) -> list:
        """Gravity parts alone (evaluated body group by body group), then the
        other forces in groups of one kind."""
        gravity = [f for f in self.forces if isinstance(f, Gravity)]
        others = tuple(f for f in self.forces if not isinstance(f, Gravity))
        return [*gravity, *self._part_groups(others)]

    def _slot_coordinates(self, group: Group, *xs: Vector) -> tuple[tuple[Vector, ...], ...]:
        return tuple(tuple(gather(x, cols) for cols in group.columns) for x in xs)

    def tangents(self, q: Vector, v: Vector, t: Scalar) -> tuple[Matrix, Matrix]:
        K = self._body_matrix(lambda b, qb, vb: b.tangents(qb, vb)[0], q, v)
        C = self._body_matrix(lambda b, qb, vb: b.tangents(qb, vb)[1], q, v)
        for parts in self._force_parts():
            if isinstance(parts, Gravity):
                continue
            group, stacked, bodies, member = parts
            if not member.depends_on_state(self._bodies_of(member)):
                continue

            def local(part, bodies, qs, vs):
                return part.generalized(bodies, qs, vs, t)

            qs, vs = self._slot_coordinates(group, q, v)
            dq = call(group, jax.jacfwd(local, argnums=2), stacked, bodies, qs, vs)
            dv = call(group, jax.jacfwd(local, argnums=3), stacked, bodies, qs, vs) if member.velocity_dependent \
                else None
            for i, rows in enumerate(group.columns):
                for j, cols in enumerate(group.columns):
                    K = scatter_block(K, rows, cols, -dq[i][j])
                    if dv is not None:
                        C = scatter_block(C, rows, cols, -dv[i][j])
        return K, C

    def _constraint_parts(self) -> tuple[AbstractConstraint, ...]:
        return (*self.joints, *self.contacts)

    def _constraint_vector(self, q: Vector, which: str) -> ConstraintVector:
        """The ``which`` constraints (see :meth:`_row_groups`), assembled."""
        offset = self.n_bilateral if which == "unilateral" else 0
        size = {"bilateral": self.n_bilateral, "unilateral": self.n_unilateral}.get(which, self.n_constraints)
        g = jnp.zeros((size,), q.dtype)
        for group, module, bodies, fn, _ in self._row_groups(which):
            rows = shift(group.rows, -offset)
            (qs,) = self._slot_coordinates(group, q)
            g = g.at[rows].set(call(group, fn, module, bodies, qs))
        return g

    def bilateral(self, q: Vector) -> ConstraintVector:
        return self._constraint_vector(q, "bilateral")

    def unilateral(self, q: Vector) -> ConstraintVector:
        return self._constraint_vector(q, "unilateral")

    def constraints(self, q: Vector) -> ConstraintVector:
        return self._constraint_vector(q, "all")

    @property
    def restitution(self) -> ConstraintVector:
        rows = [c.restitution(self._bodies_of(c)) for c in self.contacts]
        return jnp.concatenate(rows) if rows else jnp.zeros((0,))

    def _jacobian_rows(self, q: Vector, bilateral_only: bool) -> Matrix:
        rows = self.n_bilateral if bilateral_only else self.n_constraints
        G = jnp.zeros((rows, self.n_dof), q.dtype)
        for group, module, bodies, fn, _ in self._row_groups("bilateral" if bilateral_only else "all"):
            (qs,) = self._slot_coordinates(group, q)
            blocks = call(group, jax.jacfwd(fn, argnums=2), module, bodies, qs)
            for cols, block in zip(group.columns, blocks):
                G = scatter_block(G, group.rows, cols, block)
        return G

    def constraint_jacobian(self, q: Vector) -> Matrix:
        """g_q (nc, n), assembled from each part's ``jax.jacfwd`` on its own bodies' coordinates."""
        return self._jacobian_rows(q, bilateral_only=False)

    def bilateral_jacobian(self, q: Vector) -> Matrix:
        """g_q^B (nb, n), part by part."""
        return self._jacobian_rows(q, bilateral_only=True)

    def constraint_curvature(self, q: Vector, mu: ConstraintVector) -> Matrix:
        """d(g_q^T mu)/dq (n, n): each nonlinear part's Hessian of ``mu · g`` on its
        own bodies' coordinates (affine parts add nothing)."""
        H = jnp.zeros((self.n_dof, self.n_dof), q.dtype)
        for group, module, bodies, fn, linear in self._row_groups():
            if linear:
                continue

            def weighted(module, bodies, qs, weights, fn=fn):
                return weights @ fn(module, bodies, qs)

            (qs,) = self._slot_coordinates(group, q)
            local = call(group, jax.hessian(weighted, argnums=2), module, bodies, qs, mu[group.rows])
            for i, rows in enumerate(group.columns):
                for j, cols in enumerate(group.columns):
                    H = scatter_block(H, rows, cols, local[i][j])
        return H

    def velocity_constraint_gradient(self, q: Vector, v: Vector, bilateral_only: bool = False) -> Matrix:
        """G^s = d(g_q v)/dq (nc or nb, n) (eq. 50), part by part (affine parts: zero rows)."""
        rows = self.n_bilateral if bilateral_only else self.n_constraints
        out = jnp.zeros((rows, self.n_dof), q.dtype)
        for group, module, bodies, fn, linear in self._row_groups("bilateral" if bilateral_only else "all"):
            if linear:
                continue

            def rate(module, bodies, qs, vs, fn=fn):
                return jax.jvp(lambda x: fn(module, bodies, x), (qs,), (vs,))[1]

            qs, vs = self._slot_coordinates(group, q, v)
            blocks = call(group, jax.jacfwd(rate, argnums=2), module, bodies, qs, vs)
            for cols, block in zip(group.columns, blocks):
                out = scatter_block(out, group.rows, cols, block)
        return out

    # -------------------------------------------------------------- monitors
    def energy(self, q: Vector, v: Vector) -> Scalar:
        """Kinetic + strain energy of the bodies, plus the potential of every
        conservative force [J] (gravity's ``-f_g · q``)."""
        energy = 0.5 * v @ self.mass_product(q, v)
        for group, stacked in self._body_groups():
            (cols,) = group.columns
            energy = energy + jnp.sum(call(group, lambda b, qb: b.strain_energy(qb), stacked, gather(q, cols)))
        for parts in self._force_parts():
            if isinstance(parts, Gravity):
                energy = energy - self._gravity_vector(parts, q.dtype) @ q
                continue
            group, stacked, bodies, _ = parts
            (qs,) = self._slot_coordinates(group, q)
            energy = energy + jnp.sum(call(group, lambda p, bodies, qs: p.potential(bodies, qs), stacked, bodies, qs))
        return energy

    def _gravity_vector(self, gravity: Gravity, dtype) -> Vector:
        """The generalised force (n,) of a gravity part, body group by body group."""
        f = jnp.zeros((self.n_dof,), dtype)
        for group, stacked in self._body_groups(gravity.bodies):
            (cols,) = group.columns
            f = scatter_vector(f, cols, call(group, lambda b: gravity.on_body(b, dtype), stacked))
        return f

    @property
    def has_energy(self) -> bool:
        """Whether every force is conservative (a prescribed load is not)."""
        return all(f.conservative for f in self.forces)

    def angular_speed(self, q: Vector, v: Vector) -> float | None:
        slices = self._slices()
        speeds = [s for b, name in zip(self.bodies, self.body_names)
                  if (s := b.angular_speed(q[slices[name]], v[slices[name]])) is not None]
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
