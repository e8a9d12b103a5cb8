"""Where nsga_jax leans on a library's internals, experimental APIs or a
known defect: in one place, so that a new release of JAX, jaxlib or
equinox is checked here and nowhere else.

- **JAX options read at run time** (``jax.config`` declares none of them to
  type checkers): :func:`jax_option`.
- **Experimental JAX APIs**: the persistent compilation cache's reset
  (:func:`reset_compilation_cache`), gathering arrays over processes
  (:func:`process_allgather`), ``jax.shard_map`` without its replication
  checks (:func:`shard_members`).
- **Comparing tree structures** (jaxlib's ``PyTreeDef`` declares no
  comparison): :func:`same_treedef`.
- **equinox's enumeration metaclass**, used to extend
  ``optimistix.RESULTS`` with nsga_jax's failures: :func:`extend_enumeration`.
- **XLA's slow CPU reduction** of element terms taken from shifted slices
  (a chain's neighbouring nodes): :func:`dot_sum`.
- **jaxlib 0.10's LAPACK deadlock** on several CPU devices:
  :func:`bounded_lapack_batches` and :func:`lapack_batches_bounded`.

Importing this module imports JAX, but changes no JAX option.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import math
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

import jax
import jax.numpy as jnp

F = TypeVar("F", bound=Callable[..., Any])


# ------------------------------------------------------------ JAX's options and experimental APIs


def dot_sum(x: jax.Array) -> jax.Array:
    """The sum of every entry of ``x``, as a dot product with ones. Where the
    entries are products of shifted slices (a chain's element energies,
    under ``vmap``) XLA's CPU reduction runs several times slower than this
    dot (``experiments/benchmarks/bench_energy.py``; docs/performance.md,
    *Sweeps*)."""
    flat = jnp.reshape(x, (-1,))
    return flat @ jnp.ones_like(flat)


def jax_option(name: str) -> Any:
    """The value of JAX's option ``name`` (``"jax_enable_x64"``, ...)."""
    return getattr(jax.config, name)


def reset_compilation_cache() -> None:
    """Forget the persistent compilation cache JAX has opened, so that the next
    compilation opens the folder now configured."""
    from jax.experimental.compilation_cache import compilation_cache

    compilation_cache.reset_cache()


def process_allgather(tree: Any) -> Any:
    """Every process's slices of the (multi-host) arrays of ``tree``, whole on
    every process (concatenated along the leading axis)."""
    from jax.experimental import multihost_utils

    return multihost_utils.process_allgather(tree, tiled=True)


def broadcast_one_to_all(x: Any) -> Any:
    """Process 0's value of ``x``, on every process."""
    from jax.experimental import multihost_utils

    return multihost_utils.broadcast_one_to_all(x)


def shard_members(fn: F, mesh: Any, spec: Any) -> F:
    """``fn`` split over ``mesh`` by ``jax.shard_map``, every argument and
    result split along ``spec``; no replication check (the members never
    communicate)."""
    return jax.shard_map(fn, mesh=mesh, in_specs=spec, out_specs=spec, check_vma=False)


def same_treedef(a: Any, b: Any) -> bool:
    """Whether two pytrees have the same structure."""
    left: Any = jax.tree_util.tree_structure(a)
    return bool(left == jax.tree_util.tree_structure(b))


def extend_enumeration(base: Any, name: str, members: dict[str, str], module: str, doc: str) -> Any:
    """A subclass of the equinox enumeration ``base`` (``optimistix.RESULTS``)
    with the extra ``members`` (name -> message), built by equinox's
    enumeration metaclass from a class namespace."""
    meta: Any = type(base)
    return meta(name, (base,), {"__module__": module, "__doc__": doc, **members})


# ------------------------------------------------------------ jaxlib's LAPACK batches

LAPACK_WORK_PER_CALL = 2**15
"""The most work (matrices × n³) one LAPACK call is given under
:func:`bounded_lapack_batches`: a fifth of the most that jaxlib 0.10.2's CPU
LU was seen to run on its calling thread. It split batches of 2.2e5 and more
over its thread pool (128 matrices of 12 × 12, 16 of 27 × 27), and none of
1.6e5 or less (8 of 27 × 27, 32 of 16 × 16;
``experiments/tools/lapack_batch_threads.py``)."""

_BOUNDED = contextvars.ContextVar("nsga_jax_bounded_lapack_batches", default=False)


@contextlib.contextmanager
def bounded_lapack_batches(enabled: bool = True) -> Iterator[None]:
    """Trace the LAPACK calls wrapped by :func:`lapack_batches_bounded` (LU
    factorisations and solves, inverses) so that ``vmap`` over them hands
    LAPACK at most :data:`LAPACK_WORK_PER_CALL` of work per call: a batch of
    large matrices becomes a loop over chunks (one matrix per call for the
    flexible pendulum's 27 × 27), a batch of small ones stays one call.

    jaxlib 0.10's CPU LAPACK kernels split a large batch over XLA's intra-op
    thread pool and block their thread until the parts are done. When several
    host devices run such calls at once, every thread of the pool can be
    blocked that way with none left to do the parts: the flexible pendulum's
    batch of 64 on 2 forced CPU devices deadlocked so (both pool threads
    waiting in ``lapack_dgetrf``). A call below the splitting size runs on
    its own thread and cannot wait on the pool.
    :class:`~nsga_jax._batch.BatchRun` traces a batch split over several CPU
    devices with this on. The calls are the same LAPACK routines.

    The setting is read when a function is traced: a jitted function traced
    earlier keeps the trace it had (jit a separate function object for each
    setting). Only the innermost ``vmap`` over a call is chunked.
    """
    token = _BOUNDED.set(enabled)
    try:
        yield
    finally:
        _BOUNDED.reset(token)


def lapack_batches_bounded(fn: F) -> F:
    """``fn`` (a LAPACK-backed function of arrays whose first argument is the
    matrix, shape (..., n, n)), whose ``vmap`` is chunked when traced under
    :func:`bounded_lapack_batches`."""
    chunked = jax.custom_batching.custom_vmap(fn)

    @chunked.def_vmap
    def rule(axis_size, in_batched, *args):
        matrix = args[0]
        work = math.prod(matrix.shape[int(in_batched[0]):-2]) * matrix.shape[-1] ** 3
        chunk = max(1, min(axis_size, LAPACK_WORK_PER_CALL // max(work, 1)))
        batched = [a for a, b in zip(args, in_batched) if b]

        def call(members):
            it = iter(members)
            return fn(*[next(it) if b else a for a, b in zip(args, in_batched)])

        if chunk == axis_size:
            out = jax.vmap(call)(batched)
        else:
            out = jax.lax.map(call, batched, batch_size=chunk)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    @functools.wraps(fn)
    def dispatch(*args):
        return (chunked if _BOUNDED.get() else fn)(*args)

    return dispatch  # type: ignore[return-value]
