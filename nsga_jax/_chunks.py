"""Records on disk as a run goes: :class:`RecordFiles` is what
``SaveAt(chunks=folder)`` makes :func:`~nsga_jax.simulate` do: the kept
records (every ``SaveAt.every``-th step and the last, the rows of the
solution) gathered over chunks of steps into few files ``chunk_XXXXX.npz``,
each written whole (through a temporary name), at the latest every
:data:`FILE_SECONDS` and at once when the run stops or is interrupted, so an
interrupted run loses nothing already computed and a long strided run writes
what it keeps, not every step. :func:`chunk_files` writes every step of each
chunk, one file per chunk (an ``on_chunk`` callback); :func:`load_chunks`
reads a folder back. How many steps a chunk has: :func:`chunk_length` and
:func:`chunk_plan`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from ._integrators.records import StepOutput

if TYPE_CHECKING:
    from ._models.base import Model

RECORD_FIELDS = ("t", "q", "v", "lam", "nu", "impulse", "gap", "bilateral", "bilateral_rate", "result")
"""The record fields each chunk file holds, besides the Newton statistics
(``iterations`` and ``residual``, (steps, k), with the sub-problems' names in ``subproblems``)."""



FILE_NUMBERS = 2**22
"""Numbers held by one file of :class:`RecordFiles` at most (32 MB in float64)."""

FILE_SECONDS = 10.0
"""Kept records wait at most this long in memory before they are written."""


def _arrays(records: StepOutput) -> dict[str, np.ndarray]:
    """The arrays a chunk file holds of ``records``."""
    arrays = {f: np.asarray(getattr(records, f)) for f in RECORD_FIELDS}
    arrays.update(iterations=np.asarray(records.newton.iterations), residual=np.asarray(records.newton.residual))
    return arrays


def _save(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """``path`` written whole: through a temporary name, then renamed."""
    tmp = path.with_name(path.stem + ".tmp.npz")
    np.savez(tmp, **cast(dict[str, Any], arrays))  # numpy's stub would let **arrays fill allow_pickle
    tmp.rename(path)


class RecordFiles:
    """The kept records of a run, written to ``folder`` as ``chunk_XXXXX.npz``
    in few files: rows are gathered until a file would hold
    :data:`FILE_NUMBERS` numbers, or :data:`FILE_SECONDS` have passed since
    the last file, and :meth:`flush` writes what is gathered (the run's end,
    an interruption). The folder is created with the first file."""

    def __init__(self, folder: str | Path, seconds: float = FILE_SECONDS, numbers: int = FILE_NUMBERS):
        self.folder, self.seconds, self.numbers = Path(folder), seconds, numbers
        self.pending: list[dict[str, np.ndarray]] = []
        self.rows = self.files = 0
        self.subproblems: np.ndarray | None = None
        self.last = time.monotonic()

    def add(self, records: StepOutput) -> None:
        """Gather the kept ``records`` of one chunk; write a file when enough
        rows or time have gathered."""
        if len(records.t):
            arrays = _arrays(records)
            self.pending.append(arrays)
            self.rows += len(records.t)
            self.subproblems = np.asarray(records.newton.names)
            per_row = sum(a[0].size for a in arrays.values())
            if self.rows * per_row >= self.numbers or time.monotonic() - self.last >= self.seconds:
                self.flush()

    def flush(self) -> None:
        """Write the gathered rows as the next file (nothing when none)."""
        if self.pending:
            assert self.subproblems is not None
            self.folder.mkdir(parents=True, exist_ok=True)
            arrays = {k: np.concatenate([p[k] for p in self.pending]) for k in self.pending[0]}
            _save(self.folder / f"chunk_{self.files:05d}.npz", {**arrays, "subproblems": self.subproblems})
            self.files += 1
            self.pending, self.rows = [], 0
        self.last = time.monotonic()


def chunk_files(folder: str | Path, then: Callable[[int, StepOutput], None] | None = None):
    """An ``on_chunk`` callback that saves chunk k's records, every step of
    it, as ``folder/chunk_XXXXX.npz``, then calls ``then(k, records)`` if
    given (``SaveAt(chunks=folder)`` writes the kept steps only:
    :class:`RecordFiles`)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)

    def write(k: int, records: StepOutput) -> None:
        _save(folder / f"chunk_{k:05d}.npz", {**_arrays(records), "subproblems": np.asarray(records.newton.names)})
        if then is not None:
            then(k, records)

    return write



def load_chunks(out_dir: Path, folder: str = "partial") -> dict[str, np.ndarray]:
    """Concatenate the chunk files in ``DIR/partial`` (what an interrupted run
    of the command line kept: every ``record_every``-th step); any folder
    ``SaveAt(chunks=folder)`` or :func:`chunk_files` wrote is
    ``load_chunks(folder, ".")``. ``subproblems`` names the columns of
    ``iterations`` and ``residual``."""
    files = sorted((Path(out_dir) / folder).glob("chunk_?????.npz"))
    if not files:
        return {}
    parts = [dict(np.load(f)) for f in files]
    return {k: parts[0][k] if k == "subproblems" else np.concatenate([p[k] for p in parts]) for k in parts[0]}


def kept_rows(folder: str | Path) -> int:
    """The number of steps whose records the chunk files in ``folder`` hold."""
    rows = 0
    for path in sorted(Path(folder).glob("chunk_?????.npz")):
        with np.load(path) as data:
            rows += len(data["t"])
    return rows


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
    model's first output comes after a few of its steps, and a chunk's host
    work (its records, energies, totals) stays within the noise of a step
    (both measured in docs/performance.md, *The first minute of a large
    run*)."""
    fit = 2**18 // (2 * model.n_dof + 16)
    return int(min(4096, max(4, 2 ** int(math.floor(math.log2(max(fit, 1)))))))
