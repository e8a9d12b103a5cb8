"""What a sweep checks before any of its batches is compiled: each batch's
dense matrices against the memory (:func:`~nsga_jax._memory.check_fits`), its
first step against the time limit (:func:`~nsga_jax._first_step.check_first_step`,
process 0 deciding), and the redundancy of its members' joints
(:func:`~nsga_jax._run_inputs.redundancy_notes`)."""

from __future__ import annotations

import warnings

import numpy as np

from ._distributed import agree
from ._first_step import check_first_step
from ._grid import Member
from ._memory import check_fits
from ._models.redundancy import RedundantConstraintsWarning
from ._results import ConfigError
from ._run_inputs import redundancy_notes


def check_batches(batches: list[list[Member]], per_device: int, first_step_limit: float | None) -> list[str]:
    """Refuse, by name, a batch that cannot fit or whose first step (of
    ``per_device`` members) is estimated above ``first_step_limit`` [s]; warn
    each distinct redundancy report of the batches' first members once and
    return them."""
    notes: list[str] = []
    for batch in batches:  # each structure's dense matrices for a whole batch
        first = batch[0].scene
        what = f"a batch of {first.name}"
        check_fits(first.model, first.scheme(), np.dtype(first.solver["dtype"]).itemsize, members=per_device,
                   what=what)
        try:  # each process times its own LU rate: process 0 decides, so that none waits for another forever
            check_first_step(first.model, first.scheme(), first.solver["dtype"], limit=first_step_limit,
                             members=per_device, what=what)
            refused = None
        except ConfigError as error:
            refused = error
        if agree(refused is not None):
            raise refused or ConfigError(f"{what}: process 0 refused its first step (first_step_limit); its "
                                         "error names the estimate")
        with warnings.catch_warnings():  # warned below, each once
            warnings.simplefilter("ignore", RedundantConstraintsWarning)
            notes += [n for n in redundancy_notes(first.model, first.q0) if n not in notes]
    for note in notes:  # before anything is compiled, as for simulate and simulate_batch
        warnings.warn(note, RedundantConstraintsWarning, stacklevel=3)
    return notes


__all__ = ["check_batches"]
