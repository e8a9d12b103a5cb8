"""Records on disk in chunks: each finished chunk of steps is one file
``chunk_XXXXX.npz``, written whole (through a temporary name) as soon as the
chunk is done, so an interrupted run loses nothing already computed.
:func:`chunk_files` is what ``SaveAt(chunks=folder)`` makes
:func:`~nsga_jax.simulate` do; :func:`load_chunks` reads a folder back.
How many steps a chunk has: :func:`chunk_length` and :func:`chunk_plan`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from .integrators.records import StepOutput

if TYPE_CHECKING:
    from .models.base import Model

RECORD_FIELDS = ("t", "q", "v", "lam", "nu", "impulse", "gap", "bilateral", "bilateral_rate", "result")
"""The record fields each chunk file holds, besides the Newton statistics
(``iterations`` and ``residual``, (steps, k), with the sub-problems' names in ``subproblems``)."""



def chunk_files(folder: str | Path, then: Callable[[int, StepOutput], None] | None = None):
    """An ``on_chunk`` callback that saves chunk k's records as
    ``folder/chunk_XXXXX.npz`` (what ``SaveAt(chunks=folder)`` makes
    :func:`~nsga_jax.simulate` do), then calls ``then(k, records)`` if given."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)

    def write(k: int, records: StepOutput) -> None:
        arrays = {f: np.asarray(getattr(records, f)) for f in RECORD_FIELDS}
        arrays.update(iterations=np.asarray(records.newton.iterations), residual=np.asarray(records.newton.residual),
                      subproblems=np.asarray(records.newton.names))
        tmp = folder / f"chunk_{k:05d}.tmp.npz"
        np.savez(tmp, **cast(dict[str, Any], arrays))  # numpy's stub would let **arrays fill allow_pickle
        tmp.rename(folder / f"chunk_{k:05d}.npz")
        if then is not None:
            then(k, records)

    return write



def load_chunks(out_dir: Path, folder: str = "partial") -> dict[str, np.ndarray]:
    """Concatenate the chunk files in ``DIR/partial`` (an interrupted run) or
    ``DIR/steps`` (every step of a run with ``record_every > 1``); any folder
    ``SaveAt(chunks=folder)`` wrote is ``load_chunks(folder, ".")``. ``subproblems``
    names the columns of ``iterations`` and ``residual``."""
    files = sorted((Path(out_dir) / folder).glob("chunk_?????.npz"))
    if not files:
        return {}
    parts = [dict(np.load(f)) for f in files]
    return {k: parts[0][k] if k == "subproblems" else np.concatenate([p[k] for p in parts]) for k in parts[0]}


def chunk_plan(n_steps: int, length: int, done: int = 0,
               cap: Callable[[], int] | None = None) -> Iterator[tuple[int, int]]:
    """``(first, count)`` of each chunk of a run of ``n_steps`` steps after the
    ``done`` already taken: the step number of the chunk's first step and its
    number of steps (at most ``length``, and at most ``cap()`` where given,
    asked before each chunk: fewer steps where a step is slow, so that
    progress shows; the compiled chunk takes its count at run time).
    Python integers: a run's step count may pass 2**31, a chunk's never does."""
    while done < n_steps:
        count = min(length, n_steps - done, length if cap is None else max(1, cap()))
        yield done + 1, count
        done += count


def chunk_length(model: Model) -> int:
    """Steps per compiled chunk, from the model's size alone (so h and parameter
    values never change it): a power of two between 4 and 4096, about 2**18
    recorded numbers per chunk (4096 steps for a ball, 512 for the 201-node
    bar, 128 for the 648-dof cube, 4 from 16,384 coordinates). Progress is
    shown after each chunk and a step's time grows with n, so a large
    model's first output comes after a few of its steps: 64, the floor
    before, took about 2 minutes on the cube at 40 divisions. A chunk's host
    work (its records, energies, totals) measured 10 ms at 14,739
    coordinates, within the noise of a 0.1 s step (docs/performance.md)."""
    fit = 2**18 // (2 * model.n_dof + 16)
    return int(min(4096, max(4, 2 ** int(math.floor(math.log2(max(fit, 1)))))))
