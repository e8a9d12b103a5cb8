"""Groups of like parts, evaluated with one ``vmap`` each.

A chain of fifty links has fifty pins of the same kind between bodies of
the same kind. Evaluated one by one, each would add its own operations to
every function of the step (constraints, their Jacobian, curvature, G^s),
and both the compile time and the time per step would grow with the number
of parts times the operations of one. Parts of the same class, the same
static structure and leaf shapes, acting on bodies of the same kind, are
instead stacked (their leaves along a new leading axis) and evaluated by
one ``vmap``, with their bodies' coordinates gathered by one static index
array per body slot, and their results scattered back the same way, as
:mod:`nsga_jax._assembly` does for elements.

A group of one part is evaluated directly, on slices of the coordinates,
so that a system of one body of each kind runs the same operations as a
hand-written model of it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Hashable, Sequence
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Vector


def kind_of(module: Any) -> Hashable:
    """What must be equal for two modules to share a ``vmap``: the class, the
    static fields (but the names of the bodies a part acts on, which only
    say where its coordinates are gathered from) and the shape and dtype of
    every leaf."""
    leaves = jax.tree_util.tree_leaves(module)
    names = set(getattr(module, "bodies", ()))  # a part's; a body has none
    static = tuple((f.name, value) for f in dataclasses.fields(module) if f.metadata.get("static")
                   and not _names_bodies(value := getattr(module, f.name), names))
    return (type(module), static, tuple((jnp.shape(x), jnp.result_type(x)) for x in leaves))


def _names_bodies(value: Any, names: set[str]) -> bool:
    if isinstance(value, str):
        return value in names
    return isinstance(value, tuple) and len(value) > 0 and all(isinstance(v, str) and v in names for v in value)


def stack(modules: Sequence[Any]) -> Any:
    """Modules of one kind as one module with a leading axis on every leaf
    (the first member's static fields stand for all)."""
    flat = [jax.tree_util.tree_flatten(m) for m in modules]
    leaves = [jnp.stack(xs) for xs in zip(*(f[0] for f in flat))]
    return jax.tree_util.tree_unflatten(flat[0][1], leaves)


class Group(NamedTuple):
    """Members of one kind (static).

    Attributes:
        members: positions of the members in their tuple of parts (or bodies).
        columns: per body slot, the global coordinate indices of each
            member's body in that slot, shape (m, k_slot) (a slice for a group of one).
        rows: the constraint rows of each member, shape (m, count) (constraints only).
    """

    members: tuple[int, ...]
    columns: tuple[Any, ...]
    rows: Any = None

    @property
    def single(self) -> bool:
        return len(self.members) == 1


def group_by_kind(keys: Sequence[Hashable]) -> list[list[int]]:
    """Positions with equal keys, in order of first appearance."""
    groups: dict[Hashable, list[int]] = {}
    for i, key in enumerate(keys):
        groups.setdefault(key, []).append(i)
    return list(groups.values())


def columns_of(slices: Sequence[slice]) -> Any:
    """Global indices (m, k) of m bodies' coordinates, or the slice of a single one."""
    if len(slices) == 1:
        return slices[0]
    return np.stack([np.arange(s.start, s.stop) for s in slices]).astype(np.int32)


def gather(x: Vector, columns: Any) -> jax.Array:
    """The coordinates of a slot: (k,) for a single member, (m, k) for a group."""
    return x[columns]


def call(group: Group, fn: Callable, module: Any, *args: Any) -> Any:
    """``fn(module, *args)`` for a group of one, else ``vmap(fn)`` over the stacked members."""
    return fn(module, *args) if group.single else jax.vmap(fn)(module, *args)


def scatter_vector(x: Vector, columns: Any, values: jax.Array) -> Vector:
    """``x`` with a slot's values added at its columns. A slice's values are
    padded to x's length and added (an elementwise sum the compiler fuses;
    on the CPU a scatter-add is a loop of its own, and a small system's step
    holds dozens of them)."""
    if isinstance(columns, slice):
        return x + jnp.pad(values, (columns.start, x.shape[0] - columns.stop))
    return x.at[columns].add(values)


def scatter_block(A: jax.Array, rows: Any, columns: Any, values: jax.Array) -> jax.Array:
    """``A`` with member blocks (m, r, k) (or one (r, k)) added at rows × columns
    (two slices: padded and added, as in :func:`scatter_vector`)."""
    if isinstance(rows, slice) and isinstance(columns, slice):
        pads = ((rows.start, A.shape[0] - rows.stop), (columns.start, A.shape[1] - columns.stop))
        return A + jnp.pad(values, pads)
    if isinstance(rows, slice):
        return A.at[rows, columns].add(values)
    return A.at[rows[:, :, None], columns[:, None, :]].add(values)


def shift(rows: Any, offset: int) -> Any:
    """Row indices (a slice or an index array) moved by ``offset``."""
    if isinstance(rows, slice):
        return slice(rows.start + offset, rows.stop + offset)
    return rows + offset
