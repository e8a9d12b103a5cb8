"""Where each part of a system is: the static bookkeeping of
:class:`~nsga_jax._system.model.SystemModel` (each body's slice of the
coordinates, the groups of like parts and their rows), as functions of the
model.

They are plain functions rather than methods: an equinox Module wraps each
method it hands out in a bound-method pytree, which flattens the whole model
(fifty bodies, fifty joints) on every access, and the step's tracing asks for
these thousands of times.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from .._custom_types import Vector
from .._models.coupling import BodyCoupling
from .base import GROUND, AbstractBody, AbstractConstraint, Ground
from .groups import Group, columns_of, gather, group_by_kind, kind_of, stack

if TYPE_CHECKING:
    from .model import SystemModel


@functools.cache
def ground(dim: int) -> Ground:
    """The fixed frame of a ``dim``-dimensional system (one instance per dim)."""
    return Ground(dim)


def body_slices(model: SystemModel) -> dict[str, slice]:
    """Each body's slice of the global coordinates (static)."""
    out, start = {GROUND: slice(0, 0)}, 0
    for body, name in zip(model.bodies, model.body_names):
        out[name] = slice(start, start + body.n_dof)
        start += body.n_dof
    return out


def body(model: SystemModel, name: str) -> AbstractBody:
    if name == GROUND:
        return ground(model.dim)
    return model.bodies[model.body_names.index(name)]


def bodies_of(model: SystemModel, part) -> tuple[AbstractBody, ...]:
    return tuple(body(model, name) for name in part.bodies)


def gather_part(model: SystemModel, x: Vector, part) -> tuple[Vector, ...]:
    slices = body_slices(model)
    return tuple(x[slices[name]] for name in part.bodies)


def body_groups(model: SystemModel, names: tuple[str, ...] | None = None) -> list[tuple[Group, Any]]:
    """The bodies (those named, default all) in groups of one kind, each
    with its stacked bodies (the body itself for a group of one)."""
    slices = body_slices(model)
    chosen = [i for i, name in enumerate(model.body_names) if names is None or name in names]
    out = []
    for members in group_by_kind([kind_of(model.bodies[i]) for i in chosen]):
        idx = tuple(chosen[m] for m in members)
        group = Group(idx, (columns_of([slices[model.body_names[i]] for i in idx]),))
        out.append((group, stacked([model.bodies[i] for i in idx])))
    return out


def stacked(modules: list) -> Any:
    return modules[0] if len(modules) == 1 else stack(modules)


def part_groups(model: SystemModel, parts: tuple, first_row: int | None = None) -> list[tuple[Group, Any, tuple, Any]]:
    """Parts in groups of one kind acting on bodies of one kind each: the
    group (with each member's rows from ``first_row`` on, for constraints),
    the stacked parts, the stacked bodies of each slot, and the first
    member (whose static answers stand for the group's)."""
    slices = body_slices(model)
    starts, row = [], first_row or 0
    for part in parts:
        starts.append(row)
        if first_row is not None:
            row += part.count(bodies_of(model, part))
    keys = [(kind_of(p), tuple(kind_of(b) for b in bodies_of(model, p))) for p in parts]
    out = []
    for members in group_by_kind(keys):
        chosen = [parts[m] for m in members]
        columns = tuple(columns_of([slices[p.bodies[s]] for p in chosen]) for s in range(len(chosen[0].bodies)))
        rows = None
        if first_row is not None:
            count = chosen[0].count(bodies_of(model, chosen[0]))
            rows = (slice(starts[members[0]], starts[members[0]] + count) if len(members) == 1 else
                    np.stack([np.arange(starts[m], starts[m] + count) for m in members]).astype(np.int32))
        bodies = tuple(stacked([bodies_of(model, p)[s] for p in chosen]) for s in range(len(columns)))
        out.append((Group(tuple(members), columns, rows), stacked(chosen), bodies, chosen[0]))
    return out


def row_groups(model: SystemModel, which: str = "all") -> list[tuple[Group, Any, tuple, Callable, bool]]:
    """The groups of constraint rows (rows of ``[g^B; g^U]``) of ``which``
    constraints (``"bilateral"``, ``"unilateral"`` or ``"all"``):
    ``(group, module, slot bodies, fn(module, bodies, qs) -> rows,
    is_linear)``; the bodies' own constraints first, then the joints,
    then the contacts."""
    out: list[tuple[Group, Any, tuple, Callable, bool]] = []
    if which != "unilateral":
        starts = np.cumsum([0] + [b.n_bilateral for b in model.bodies])
        own = tuple(name for b, name in zip(model.bodies, model.body_names) if b.n_bilateral)
        for group, stacked in body_groups(model, own):
            count = model.bodies[group.members[0]].n_bilateral
            first = [int(starts[m]) for m in group.members]
            rows = (slice(first[0], first[0] + count) if group.single else
                    np.stack([np.arange(f, f + count) for f in first]).astype(np.int32))
            out.append((group._replace(rows=rows), stacked, (stacked,),
                        lambda body, bodies, qs: body.bilateral(qs[0]), False))
    sections: list[tuple[tuple, int]] = []
    if which != "unilateral":
        sections.append((model.joints, model.n_own_bilateral))
    if which != "bilateral":
        sections.append((model.contacts, model.n_bilateral))
    for parts, first_row in sections:
        for group, stacked, bodies, first in part_groups(model, parts, first_row):
            out.append((group, stacked, bodies, lambda part, bodies, qs: part.evaluate(bodies, qs),
                        first.is_linear(bodies_of(model, first))))
    return out


def slot_coordinates(model: SystemModel, group: Group, *xs: Vector) -> tuple[tuple[Vector, ...], ...]:
    return tuple(tuple(gather(x, cols) for cols in group.columns) for x in xs)


def constraint_parts(model: SystemModel) -> tuple[AbstractConstraint, ...]:
    return (*model.joints, *model.contacts)


def named_parts(model: SystemModel):
    return (("joints", model.joints, model.joint_names), ("contacts", model.contacts, model.contact_names),
            ("forces", model.forces, model.force_names))


_WHAT = {"joints": ("a joint", "its constraint is a constant"), "contacts": ("a contact", "its gap is a constant"),
         "forces": ("a force", "it acts on nothing")}


def _body_fields(part) -> list[tuple[str, str]]:
    """``(field, body name)`` for each field of ``part`` that names a body (``body``,
    ``body_a``, ``body_b``, gravity's ``on``)."""
    out: list[tuple[str, str]] = []
    for field in dataclasses.fields(part):
        if field.name in ("body", "body_a", "body_b", "on"):
            value = getattr(part, field.name)
            out.extend((field.name, v) for v in ((value,) if isinstance(value, str) else value))
    return out


def reference_rule(model: SystemModel) -> str | None:
    """Why a part's body references cannot stand, or ``None``. Structure only
    (checked even where the values are traced): a name that is no body; a
    joint, contact or force on the ground alone (nothing moves: its gap,
    constraint or force is a constant); a joint or contact between two
    points of one rigid body (constant too, its Jacobian rows zero)."""
    moving = ", ".join(model.body_names) or "none"
    for kind, parts, names in named_parts(model):
        article, quantity = _WHAT[kind]
        for part, name in zip(parts, names):
            refs = _body_fields(part)
            for field, ref in refs:
                if ref != GROUND and ref not in model.body_names:
                    return (f"{kind}.{name}: {field} = {ref!r} names a body that does not exist "
                            f"(bodies: {moving}, ground)")
            if refs and all(ref == GROUND for _, ref in refs):
                given = " = ".join(dict.fromkeys(field for field, _ in refs))
                return (f"{kind}.{name}: {given} = 'ground', the fixed frame; {article} needs a moving body "
                        f"(one of: {moving}): on the ground alone {quantity}")
            slots = [ref for _, ref in refs]
            if kind != "forces" and len(slots) == 2 and slots[0] == slots[1] and not body(model, slots[0]).has_nodes:
                nodes = " (or two nodes of a flexible body)" if kind == "joints" else ""
                return (f"{kind}.{name}: body_a = body_b = {slots[0]!r}, a rigid body; between two points of one "
                        f"rigid body {quantity}: name two different bodies{nodes}")
    return None


def body_coupling(model: SystemModel) -> BodyCoupling:
    """Which coordinates the model's matrices couple (static): each body's
    coordinates; each row's bodies (a body's own rows, then each joint's and
    contact's on the moving bodies it names); the pairs of bodies a force
    that depends on the state acts on."""
    index = {name: i for i, name in enumerate(model.body_names)}
    slices = body_slices(model)
    dofs = tuple((slices[name].start, slices[name].stop) for name in model.body_names)
    rows: list[tuple[int, ...]] = []
    for i, b in enumerate(model.bodies):
        rows.extend([(i,)] * b.n_bilateral)
    for part in (*model.joints, *model.contacts):
        moving = tuple(sorted({index[name] for name in part.bodies if name != GROUND}))
        rows.extend([moving] * part.count(bodies_of(model, part)))
    pairs: set[tuple[int, int]] = set()
    for force in model.forces:
        acted = sorted({index[name] for name in force.bodies if name != GROUND})
        if len(acted) > 1 and force.depends_on_state(bodies_of(model, force)):
            pairs.update((a, b) for a in acted for b in acted if a < b)
    return BodyCoupling(dofs, tuple(rows), tuple(sorted(pairs)))
