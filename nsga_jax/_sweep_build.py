"""A sweep batch's models, initial states and observables from one compiled call.

The members of a sweep differ only in float scene parameters (and h). A
scene's ``make(p, concrete)`` is traceable in the floats of ``p``
(:func:`~nsga_jax.scenes.parametrize`), so a batch's models and initial
states come from one ``vmap``-ped, compiled call of ``make``, and each
member's observables from one compiled call taking its parameters as
arguments, where a Python build per member costs 3 ms (the bouncing ball)
and the impacting bar's observables, evaluated op by op, 20 ms a member
(``experiments/benchmarks/bench_sweep_overhead.py``).

Which float parameters are structure is derived from ``make``, not declared:
``make`` reads structure from its second argument (the bouncing ball's
friction coefficient decides whether its contact has friction rows; the
impacting bar's length places its observed node). A sweep that varies such a
float, or whose scene's ``make`` needs a float as a Python number, builds its
members one by one and groups them by comparing their models
(:func:`~nsga_jax._batch.same_structure`), as every sweep did before.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Hashable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._batch import same_structure, stack_models
from ._grid import Member
from ._models.base import Model
from ._scenes.spec import SceneSpec
from ._solution import Solution

ObservablesOf = Callable[[list[Solution], Solution | None], list[dict[str, np.ndarray]]]
"""The batch's members' float64 Solutions (in batch order) -> each one's ``{name: (rows,)}``."""


class _Reads(dict):
    """A scene's concrete parameters, remembering which keys ``make`` reads."""

    def __init__(self, values: dict[str, Any]):
        super().__init__(values)
        self.read: set[str] = set()

    def __getitem__(self, key):
        self.read.add(key)
        return super().__getitem__(key)

    def get(self, key, default=None):
        self.read.add(key)
        return super().get(key, default)

    def __iter__(self):  # copying or iterating reads every key
        self.read.update(super().keys())
        return super().__iter__()

    def items(self):
        self.read.update(super().keys())
        return super().items()

    def values(self):
        self.read.update(super().keys())
        return super().values()


def _floats(spec: SceneSpec) -> list[str]:
    return [k for k, p in spec.parameters.items() if p.kind == "float"]


def _traced_make(spec: SceneSpec, concrete: dict[str, Any]) -> Callable:
    """``p -> make({**concrete, **p}, concrete)``, the floats of ``p`` traced."""
    return lambda p: spec.make({**concrete, **p}, concrete)


def structural_floats(spec: SceneSpec, parameters: dict[str, Any]) -> tuple[str, ...] | None:
    """The float parameters ``spec.make`` reads as structure (from its second
    argument), found by tracing it once with every float traced; ``None``
    where ``make`` cannot be traced in its floats."""
    watched = _Reads(parameters)
    floats = _floats(spec)
    p = {k: np.asarray(parameters[k], dtype=np.float64) for k in floats}
    try:
        jax.eval_shape(lambda p: eqx.filter(spec.make({**dict(parameters), **p}, watched)[:3], eqx.is_array), p)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError,
            jax.errors.TracerIntegerConversionError):
        return None
    return tuple(k for k in floats if k in watched.read)


def traced_structure(mems: list[Member]) -> tuple[str, ...] | None:
    """The float parameters the sweep's scene reads as structure, where its
    batches can be built traced: ``None`` where ``make`` cannot be traced or
    the sweep varies one of them (a friction coefficient that decides whether
    a contact has friction rows, the bar's length that places its observed
    node), so that members are built one by one and grouped by their models."""
    first = mems[0].configured
    structural = structural_floats(first.spec, first.parameters)
    if structural is None or any(m.configured.parameters[k] != first.parameters[k] for m in mems for k in structural):
        return None
    return structural


def split_batches(mems: list[Member], batch_size: int, structural: tuple[str, ...] | None) -> list[list[Member]]:
    """The members in batches of at most ``batch_size``, in grid order, a new
    batch wherever a member differs in structure from the one before (in a
    float the scene reads as structure, ``structural``; where the scene
    cannot be traced, ``None``, in its built model): each batch is one
    compilation."""
    runs: list[list[Member]] = []
    for m in mems:
        if structural is None:
            same = bool(runs) and same_structure(m.scene.model, runs[-1][-1].scene.model)
        else:
            same = bool(runs) and all(m.configured.parameters[k] == runs[-1][-1].configured.parameters[k]
                                      for k in structural)
        if same:
            runs[-1].append(m)
        else:
            runs.append([m])
    return [run[i:i + batch_size] for run in runs for i in range(0, len(run), batch_size)]


@dataclasses.dataclass
class BatchModels:
    """A batch's stacked model (float64), initial states (B, n) and each
    member's observables and exact solution (``None`` where it has none)."""

    model: Model
    q0: np.ndarray
    v0: np.ndarray
    observables: ObservablesOf
    exact: list[Callable | None]


_COMPILED: dict[tuple[int, Hashable], tuple[SceneSpec, Callable, Callable, dict]] = {}
"""Per scene and structure: the batch build and the member observables, compiled once per process."""


def _compiled(spec: SceneSpec, parameters: dict[str, Any],
              structural: tuple[str, ...]) -> tuple[Callable, Callable, dict[Hashable, _Observer]]:
    floats = set(_floats(spec)) - set(structural)
    key = (id(spec), repr(sorted((k, v) for k, v in parameters.items() if k not in floats)))
    entry = _COMPILED.get(key)
    if entry is None or entry[0] is not spec:
        make = _traced_make(spec, dict(parameters))
        build = eqx.filter_jit(eqx.filter_vmap(lambda p: make(p)[:3]))
        observables = lambda p, sol: make(p)[3](sol)  # noqa: E731  (traced per layout, see _Observer)
        entry = _COMPILED[key] = (spec, build, observables, {})
    return entry[1], entry[2], entry[3]


class _Observer:
    """A scene's observables of a group of members' Solutions of one layout, in
    one compiled, vmapped call that takes only the arrays they read (found
    by tracing them once: an input no equation takes is not read), so that
    the members' other records are neither stacked nor copied."""

    def __init__(self, observables: Callable, p: dict[str, np.ndarray], sol: Solution):
        dynamic, self.static = eqx.partition(sol, eqx.is_array)
        leaves, self.treedef = jax.tree_util.tree_flatten(dynamic)
        self.shapes = [jax.ShapeDtypeStruct(np.shape(x), np.asarray(x).dtype) for x in leaves]

        def one(p, *read):
            it = iter(read)
            full = [next(it) if r else jnp.zeros(x.shape, x.dtype) for r, x in zip(self.read, self.shapes)]
            return observables(p, eqx.combine(jax.tree_util.tree_unflatten(self.treedef, full), self.static))

        self.read = [True] * len(leaves)
        closed = jax.make_jaxpr(one)(p, *leaves)
        taken = {id(v) for eqn in closed.jaxpr.eqns for v in eqn.invars} | {id(v) for v in closed.jaxpr.outvars}
        self.read = [id(v) in taken for v in closed.jaxpr.invars[len(jax.tree_util.tree_leaves(p)):]]
        self.call = jax.jit(jax.vmap(one))

    def __call__(self, p: dict[str, np.ndarray], sols: list[Solution] | Solution) -> dict[str, np.ndarray]:
        """The observables of the members ``sols``, or of the members stacked
        in one Solution (each leaf with a leading member axis)."""
        if isinstance(sols, Solution):
            leaves = jax.tree_util.tree_leaves(eqx.filter(sols, eqx.is_array))
            read = [x for x, r in zip(leaves, self.read) if r]
        else:
            columns = [jax.tree_util.tree_leaves(eqx.filter(s, eqx.is_array)) for s in sols]
            read = [np.stack([c[i] for c in columns]) for i, r in enumerate(self.read) if r]
        return jax.device_get(self.call(p, *read))


def _signature(sol: Solution) -> Hashable:
    dynamic, static = eqx.partition(sol, eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dynamic)
    return (treedef, tuple((np.shape(x), np.asarray(x).dtype) for x in leaves))


def _bare(sol: Solution) -> Solution:
    """``sol`` with only what observables read (arrays and h), so that the
    members of one length stack and share one compilation."""
    return dataclasses.replace(sol, result=0, stats={}, h=np.asarray(sol.h, dtype=np.float64), n_steps=0,
                               n_steps_requested=0, failed_steps=None, observables={}, wall_time=0.0,
                               compile_time=0.0, compile_source="compiled", warnings=[])


def build_batch(batch: list[Member], structural: tuple[str, ...] | None) -> BatchModels:
    """The models of ``batch`` (members of one structure, see
    :func:`split_batches`): from one compiled call where the sweep can be
    traced (``structural``, from :func:`traced_structure`: the floats the
    scene reads as structure, which no member varies), else member by
    member."""
    first = batch[0].configured
    spec = first.spec
    exact = [spec.exact(m.configured.parameters) if spec.exact is not None else None for m in batch]
    if structural is None:
        scenes = [m.scene for m in batch]

        def each(sols: list[Solution], stacked: Solution | None = None) -> list[dict[str, np.ndarray]]:
            """Member by member (``stacked`` is not read)."""
            return [{k: np.asarray(v) for k, v in scenes[b].observables(sol).items()} for b, sol in enumerate(sols)]

        return BatchModels(stack_models([s.model for s in scenes]), np.stack([s.q0 for s in scenes]),
                           np.stack([s.v0 for s in scenes]), each, exact)
    build, observables, observers = _compiled(spec, first.parameters, structural)
    p = {k: np.asarray([m.configured.parameters[k] for m in batch], dtype=np.float64) for k in _floats(spec)}
    model, q0, v0 = build(p)

    def observables_of(sols: list[Solution], stacked: Solution | None = None) -> list[dict[str, np.ndarray]]:
        """One compiled, vmapped call per group of members of one layout
        (as many rows); ``stacked``: the members' records already stacked
        (every member keeps the same steps), read as they are."""
        bare = [_bare(sol) for sol in sols]
        layouts: dict[Hashable, list[int]] = {}
        for b, sol in enumerate(bare):
            layouts.setdefault(_signature(sol), []).append(b)
        out: list[dict[str, np.ndarray]] = [{} for _ in sols]
        for signature, group in layouts.items():
            observer = observers.get(signature)
            if observer is None:
                observer = observers[signature] = _Observer(observables, {k: x[0] for k, x in p.items()},
                                                            bare[group[0]])
            members = _bare(stacked) if stacked is not None and len(layouts) == 1 else [bare[b] for b in group]
            values = observer({k: x[group] for k, x in p.items()}, members)
            for j, b in enumerate(group):
                out[b] = {k: np.asarray(v[j]) for k, v in values.items()}
        return out

    return BatchModels(model, np.asarray(q0, dtype=np.float64), np.asarray(v0, dtype=np.float64), observables_of,
                       exact)


__all__ = ["BatchModels", "build_batch", "split_batches", "structural_floats", "traced_structure"]
