"""Records on disk in chunks: each finished chunk of steps is one file
``chunk_XXXXX.npz``, written whole (through a temporary name) as soon as the
chunk is done, so an interrupted run loses nothing already computed.
:func:`chunk_files` is what ``SaveAt(chunks=folder)`` makes
:func:`~nsga_jax.simulate` do; :func:`load_chunks` reads a folder back.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

import numpy as np

from .integrators.records import StepOutput

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
