"""Many runs of one model structure in one compiled program: ``vmap`` over members.

The members of a batch share the model's static structure (sizes, element
connectivity, which constraints exist) and may differ in every array: the
parameter values (a *stacked* model, each array leaf with a leading member
axis), the initial state and the step size h. Their step counts differ with
h; the time loop is a ``while_loop`` per chunk whose trip count is traced, so
under ``vmap`` a member that has finished keeps its state while the others go
on, and every member pays for the longest run's number of steps (batching
over h pays when the step sizes are close; ``experiments/benchmarks/bench_batch_h.py``).

With a device mesh (:func:`member_mesh`) the members are split over its
devices by ``jax.shard_map``: each device runs its own members' loops with no
communication between devices until the results are gathered. That is how a
sweep uses several CPU devices, a GPU, or every device of several hosts
started with ``jax.distributed.initialize()``.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Hashable, Iterator, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ._compat import bounded_lapack_batches, process_allgather, same_treedef, shard_members
from ._first_step import LIMIT_SECONDS, check_first_step
from ._integrators.base import AbstractScheme
from ._integrators.records import StepOutput, output_template, packed_sizes, unpack_outputs
from ._memory import check_fits
from ._models.base import Model
from ._monitors import RunTotals
from ._precision import cast_floats
from ._results import ConfigError, Result
from ._run_core import constraints_at, prepare_and_init, run_chunk
from ._run_inputs import check_run_inputs
from ._simulate import chunk_length, prepend_initial
from ._solution import Observables, Solution, host_solution, with_observables
from ._validation import require_instance

MEMBERS = "members"
"""Name of the mesh axis the members are split over."""


def needs_bounded_lapack_batches(mesh: Mesh | None) -> bool:
    """Whether a batch split over ``mesh`` is traced with
    :func:`~nsga_jax._compat.bounded_lapack_batches`: when its
    members run on several CPU devices at once, where jaxlib 0.10's large
    batched LAPACK calls can deadlock XLA's shared thread pool."""
    return mesh is not None and mesh.size > 1 and mesh.devices.flat[0].platform == "cpu"


RECORD_BUDGET = 2**22
"""Recorded numbers per batched chunk (32 MiB in float64): the chunk length of
a batch is the single-run length divided by the batch size, within [16, 4096]."""


def member_mesh(devices: Sequence[jax.Device] | None = None) -> Mesh:
    """A one-axis mesh over ``devices`` (default: every device of every process)."""
    devices = jax.devices() if devices is None else list(devices)
    return Mesh(np.asarray(devices), (MEMBERS,))


def stack_models(models: Sequence[Model]) -> Model:
    """One model whose array leaves stack the members' leaves (leading axis).

    Raises :class:`ConfigError` when the members differ in static structure
    (an element count, a mass-matrix kind): those cannot share a compilation.
    """
    parts = [eqx.partition(m, eqx.is_array) for m in models]
    static = parts[0][1]
    for i, m in enumerate(models[1:], start=1):
        if not same_structure(m, models[0]):
            raise ConfigError(f"batch member {i} differs in structure from member 0 (sizes, element kinds "
                              "or other static fields); run such members in separate batches")
    dynamic = jax.tree_util.tree_map(_stack, *[d for d, _ in parts])
    return eqx.combine(dynamic, static)


def _stack(*xs):
    """The arrays ``xs`` stacked along a new leading axis: on the host and sent
    once where they are concrete (``jnp.stack`` of many device arrays took
    0.65 ms a member of a 1,024-member sweep), by ``jnp.stack`` where traced."""
    if any(isinstance(x, jax.core.Tracer) for x in xs):
        return jnp.stack(xs)
    return jnp.asarray(np.stack([np.asarray(x) for x in xs]))


def same_structure(a: Model, b: Model) -> bool:
    """Whether two models can share one compilation: the same tree, arrays of
    the same shapes and dtypes in the same places, and the same static fields
    (their arrays may differ in value). The whole tree is compared, not only
    its static part: a contact without friction has ``mu=None`` where one
    with friction has an array, and both leave ``None`` in the static part."""
    if not same_treedef(a, b):
        return False
    da, sa = eqx.partition(a, eqx.is_array)
    db, sb = eqx.partition(b, eqx.is_array)
    if not same_treedef(da, db):
        return False
    if any((x.shape, x.dtype) != (y.shape, y.dtype)
           for x, y in zip(jax.tree_util.tree_leaves(da), jax.tree_util.tree_leaves(db))):
        return False
    return same_treedef(sa, sb) and bool(eqx.tree_equal(sa, sb))


def broadcast_members(tree, n: int):
    """Every array leaf of ``tree`` repeated along a new leading axis of length n."""
    return jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n, *jnp.shape(x))) if eqx.is_array(x) else x, tree)


def batch_chunk_length(model: Model, n_members: int) -> int:
    """Steps per compiled chunk of a batch: a power of two in [16, 4096] keeping
    about :data:`RECORD_BUDGET` recorded numbers per chunk."""
    fit = RECORD_BUDGET // (n_members * (2 * model.n_dof + 16))
    return int(min(chunk_length(model), max(16, 2 ** int(np.floor(np.log2(max(fit, 1)))))))


def _on_devices(fn, mesh: Mesh | None):
    """``fn`` (which takes member-batched arguments) split over the mesh's
    devices by ``shard_map`` when a mesh is given: each device runs its own
    members, with no communication until the results are gathered."""
    if mesh is None:
        return fn
    spec = PartitionSpec(MEMBERS)
    return shard_members(fn, mesh, spec)


@functools.cache
def _compiled_steps(length: int, mesh: Mesh | None):
    """The jitted preparation and chunk programs of a batch over ``mesh``
    (traced under :func:`bounded_lapack_batches` where
    :func:`needs_bounded_lapack_batches` says so: one pair per mesh keeps the two
    tracings apart)."""
    prepare = eqx.filter_jit(_on_devices(_prepare_members, mesh))
    run = functools.partial(run_chunk, stop_on_failure=False, length=length, members=True)
    return prepare, eqx.filter_jit(_on_devices(run, mesh))


def _prepare_members(*members):
    """Constant operators and initial carry of each member, one member after
    the other (``lax.map``): it runs once per batch, and its LAPACK calls
    then stay those of one member (see :func:`needs_bounded_lapack_batches`)."""

    def one(args):
        return prepare_and_init(*args)

    return lax.map(one, members)


_members_constraints = eqx.filter_jit(jax.vmap(constraints_at))  # every member's at q0 in one call

_EXECUTABLES: dict[Hashable, tuple[Any, Callable]] = {}
"""Compiled batch programs by (program, bounded LAPACK, the arguments' tree,
shapes, dtypes, shardings and static values): the batches of a sweep that
share a structure compile once per process, not once per batch."""


def _compile(fn: Any, args: tuple, bounded: bool) -> Callable:
    """``fn`` (an ``eqx.filter_jit``) compiled for ``args``, once per signature."""
    leaves, treedef = jax.tree_util.tree_flatten(args)
    key: Hashable = (id(fn), bounded, treedef,
           tuple((x.shape, x.dtype, getattr(x, "weak_type", False), getattr(x, "sharding", None))
                 if eqx.is_array(x) else x for x in leaves))
    try:
        hit = _EXECUTABLES.get(key)
    except (TypeError, ValueError):  # an unhashable or array-valued static leaf: compile every time
        key, hit = None, None
    if hit is not None and hit[0] is fn:
        return hit[1]
    with bounded_lapack_batches(bounded):
        compiled = fn.lower(*args).compile()
    if key is not None:
        _EXECUTABLES[key] = (fn, compiled)
    return compiled


def _place(tree, mesh: Mesh | None):
    """Array leaves as global arrays split over the mesh's member axis (each
    process supplies its own devices' slices, so this works across hosts)."""
    if mesh is None:
        return tree
    sharding = NamedSharding(mesh, PartitionSpec(MEMBERS))

    def place(x):
        if not eqx.is_array(x):
            return x
        x = np.asarray(x)
        return jax.make_array_from_callback(x.shape, sharding, lambda index: x[index])

    return jax.tree_util.tree_map(place, tree)


def _to_host(tree):
    """NumPy copies of (possibly multi-host) arrays, whole on every process."""
    if jax.process_count() > 1:
        tree = process_allgather(tree)
    return jax.device_get(tree)


class BatchRun:
    """The compiled batched time loop over a fixed set of members.

    ``chunks()`` yields ``(records, done)`` per chunk of steps: NumPy
    :class:`StepOutput` with leaves of shape (B, L, ...) and the mask (B, L) of
    the steps each member took. ``compile_time`` and ``wall_time`` [s] are
    those of the whole batch (wall time: preparation and chunks until their
    results are ready, not the copies to the host). ``initial_constraints``:
    every member's gaps (B, nu) [m] and bilateral values (B, nb) at q0
    (NumPy), computed in one call for the records' initial rows.
    """

    def __init__(self, model: Model, scheme: AbstractScheme, t0, q0, v0, hs, n_steps, *,
                 mesh: Mesh | None = None, length: int | None = None):
        B = len(hs)
        if mesh is not None and B % mesh.size:
            raise ConfigError(f"the batch ({B} members) must be a multiple of the mesh's {mesh.size} devices")
        self.n_members = B
        self.longest = int(np.max(n_steps))
        self.length = length or batch_chunk_length(model, B)
        prepare, self._run = _compiled_steps(self.length, mesh)
        schemes = broadcast_members(scheme, B)
        t0s = np.full(B, t0, np.asarray(hs).dtype)  # in the precision of the step sizes
        args = _place((model, schemes, t0s, np.asarray(q0), np.asarray(v0), np.asarray(hs)), mesh)
        bounded = needs_bounded_lapack_batches(mesh)
        tc = time.perf_counter()
        prepare = _compile(prepare, args, bounded)
        self.compile_time = time.perf_counter() - tc
        tw = time.perf_counter()
        self._ops, self._carry = prepare(*args)
        jax.block_until_ready(self._carry)
        self.wall_time = time.perf_counter() - tw
        self._args = (args[0], args[1])
        self.initial_constraints = _to_host(_members_constraints(args[0], args[3]))
        self._template = output_template(model, self._carry.q.dtype, scheme.subproblems)
        self._hs = np.asarray(hs)
        self._t0 = float(t0)
        self._n_steps = np.asarray(n_steps, dtype=np.int64)
        self._done = np.zeros(B, np.int64)
        self._mesh = mesh
        dtype = self._carry.q.dtype
        tc = time.perf_counter()
        self._run = _compile(self._run, (*self._args, self._ops, self._carry, *self._chunk_args(dtype)), bounded)
        self.compile_time += time.perf_counter() - tc

    def _chunk_args(self, dtype):
        """``(h, t_start, steps)`` of every member for the next chunk: each
        member's steps left (at most a chunk's length) and the time it starts
        from, ``t0 + done h`` in float64 (never accumulated on the device)."""
        steps = np.minimum(self._n_steps - self._done, self.length).astype(np.int32)
        t_start = (self._t0 + self._done * self._hs.astype(np.float64)).astype(dtype)
        return _place((self._hs.astype(dtype), t_start, steps), self._mesh)

    @property
    def n_chunks(self) -> int:
        return -(-self.longest // self.length)

    def chunks(self) -> Iterator[tuple[StepOutput, np.ndarray]]:
        dtype = self._carry.q.dtype
        for _ in range(self.n_chunks):
            tw = time.perf_counter()
            self._carry, (packed, done) = self._run(*self._args, self._ops, self._carry, *self._chunk_args(dtype))
            jax.block_until_ready((self._carry, packed, done))
            self.wall_time += time.perf_counter() - tw
            packed, done = _to_host((packed, done))
            floats, ints = packed
            self._done += done.sum(axis=1)
            yield unpack_outputs(floats, ints, self._template), done


def joined_records(chunks: list[StepOutput], t0: float, q0: np.ndarray, v0: np.ndarray,
                   run: BatchRun) -> StepOutput:
    """Every member's (NumPy) records of ``chunks`` (each leaf (B, steps,
    ...)) after its initial row (t0, q0 (B, n), v0 (B, n) and the gaps and
    bilateral values the batch computed there): leaves (B, 1 + steps, ...),
    joined in one copy, for members that keep the same steps."""
    gap, bilateral = run.initial_constraints
    first = chunks[0]
    init = jax.tree_util.tree_map(lambda x: np.zeros((x.shape[0], 1) + x.shape[2:], x.dtype), first)
    init = eqx.tree_at(lambda r: (r.t, r.q, r.v, r.gap, r.bilateral), init,
                       (np.full((len(q0), 1), float(t0)), q0[:, None], v0[:, None], np.asarray(gap)[:, None],
                        np.asarray(bilateral)[:, None]))
    return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs, axis=1), init, *chunks)


def member_solution(model: Model, chunks: list[StepOutput], t0, q0, v0, h: float, n_steps_requested: int,
                    run: BatchRun, index: int, totals: RunTotals | None = None,
                    warnings: list[str] | None = None, joined: StepOutput | None = None) -> Solution:
    """Member ``index``'s :class:`Solution` from its (NumPy) records. Without
    ``totals`` the records hold every step and give the statistics and the
    first failure; with them (records strided) those come from ``totals``.
    ``warnings``: notes of the run kept in ``Solution.warnings`` (the
    redundancy of its constraints). ``joined``: the batch's records from
    :func:`joined_records`, of which the member's are a view (``chunks``,
    ``t0``, ``q0`` and ``v0`` are then not read)."""
    if joined is not None:
        records = jax.tree_util.tree_map(lambda x: x[index], joined)
    else:
        initial = tuple(x[index] for x in run.initial_constraints)
        records = prepend_initial(model, chunks, t0, q0, v0, constraints=initial)
    if totals is None:
        bad = np.nonzero(np.asarray(records.result) != Result.successful)[0]
        result = Result(int(records.result[bad[0]])) if bad.size else Result.successful
        n_steps = len(records.t) - 1
    else:
        result = Result(int(totals.first_result)) if totals.failed else Result.successful
        n_steps = totals.n_steps
    return host_solution(records, ts=np.asarray(records.t), h=h, n_steps=n_steps, n_steps_requested=n_steps_requested,
                         result=result, totals=totals, wall_time=run.wall_time, compile_time=run.compile_time,
                         warnings=list(warnings or []))


def simulate_batch(
    model: Model,
    scheme: AbstractScheme,
    t0: float,
    t1: float,
    hs,
    q0,
    v0,
    *,
    observables: Observables | None = None,
    dtype: str = "float64",
    mesh: Mesh | None = None,
    first_step_limit: float | None = LIMIT_SECONDS,
) -> list[Solution]:
    """Integrate one problem with every step size in ``hs`` at once (``vmap``):
    the arguments of :func:`~nsga_jax.simulate` in the same order, with a
    sequence of step sizes ``hs`` [s] in place of h; one
    :class:`~nsga_jax.Solution` (NumPy leaves) per step size.

    Failures never stop the batch (one bad member must not kill a sweep): each
    member's records carry its result codes and ``Solution.result`` its first
    failure. ``wall_time`` and ``compile_time`` are those of the whole batch.
    ``dtype`` is the precision, as in :func:`~nsga_jax.simulate`; ``mesh``
    splits the members over devices (:func:`member_mesh`; the number of step
    sizes must then be a multiple of the mesh size); ``observables`` names
    quantities of each finished member, as in :func:`~nsga_jax.simulate`;
    ``first_step_limit`` [s] refuses, before compiling, a batch whose first
    step (every member's dense factorisations, counted one after another;
    a device's members where ``mesh`` splits them over GPUs) is estimated
    above it (:func:`~nsga_jax._first_step.check_first_step`;
    ``None`` runs anyway).
    """
    run_inputs = check_run_inputs("nsga_jax.simulate_batch", model, scheme, t0, t1, q0, v0, dtype=dtype, hs=hs,
                                  observables=observables, first_step_limit=first_step_limit)
    dtype, t0, q0, v0, notes = run_inputs.dtype, run_inputs.t0, run_inputs.q0, run_inputs.v0, run_inputs.notes
    hs, n_steps = run_inputs.hs, run_inputs.n_steps
    if mesh is not None:
        require_instance("mesh", mesh, Mesh, "a jax.sharding.Mesh (nsga_jax.member_mesh)")
    template = output_template(model, np.dtype(dtype), scheme.subproblems)
    check_fits(model, scheme, np.dtype(dtype).itemsize, members=len(hs), records=int(n_steps.max()),
               record_numbers=sum(packed_sizes(template)), what="the batch")
    per_device = len(hs) if mesh is None or mesh.devices.flat[0].platform == "cpu" else len(hs) // mesh.size
    check_first_step(model, scheme, dtype, limit=first_step_limit, members=per_device, what="the batch")
    B = len(hs)
    model_c, scheme_c = cast_floats((model, scheme), dtype)
    run = BatchRun(broadcast_members(model_c, B), scheme_c, t0, np.tile(q0.astype(dtype), (B, 1)),
                   np.tile(v0.astype(dtype), (B, 1)), hs.astype(dtype), n_steps, mesh=mesh)
    chunks: list[list[StepOutput]] = [[] for _ in range(B)]
    for out, done in run.chunks():
        for b in range(B):
            if done[b].any():
                chunks[b].append(jax.tree_util.tree_map(lambda x: x[b][done[b]], out))
    return [with_observables(member_solution(model, chunks[b], t0, q0.astype(dtype), v0.astype(dtype),
                                             float(hs[b]), int(n_steps[b]), run, b, warnings=notes), observables)
            for b in range(B)]


__all__ = ["BatchRun", "broadcast_members", "member_mesh", "simulate_batch", "stack_models"]
