"""Several processes (hosts) in one sweep: ``jax.distributed``, started from checked settings.

Every process runs the same program. After :func:`initialize`,
``jax.devices()`` spans the devices of every process; a sweep's batches are
split over all of them (:mod:`nsga_jax._batch` places each process's slice of
a batch and gathers the results to every process), and process 0 writes the
files. Decisions that must be the same in every process, such as which
batches a resumed sweep may skip, are taken by process 0 and broadcast
(:func:`agree`): a process that decided on its own could wait forever in a
collective the others never enter.

On CPUs the processes talk through gloo (JAX's default CPU collectives), so
the same commands run several processes on one machine, over loopback (how
this is tested), as on several hosts.
"""

from __future__ import annotations

import jax
import numpy as np

from ._results import ConfigError


def parse_address(address: str) -> tuple[str, int]:
    """``"host:port"`` -> ``(host, port)``, port in [1, 65535]."""
    host, sep, port = address.rpartition(":")
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not sep or not host or not 1 <= number <= 65535:
        raise ConfigError(f"coordinator must be HOST:PORT with a port in [1, 65535], got {address!r}")
    return host, number


def initialize(coordinator: str, num_processes: int, process_id: int) -> None:
    """Join this process to a run of ``num_processes`` processes whose process 0
    listens at ``coordinator`` (``"host:port"``). Call it before anything else
    touches JAX's devices; it blocks until every process has joined.

    Raises :class:`ConfigError` for settings out of range, before contacting
    anyone: ``num_processes`` >= 1, ``process_id`` in [0, num_processes).
    """
    parse_address(coordinator)
    if isinstance(num_processes, bool) or not isinstance(num_processes, (int, np.integer)) or num_processes < 1:
        raise ConfigError(f"num_processes must be an integer >= 1, got {num_processes!r}")
    if (isinstance(process_id, bool) or not isinstance(process_id, (int, np.integer))
            or not 0 <= process_id < num_processes):
        raise ConfigError(f"process_id must be an integer in [0, {num_processes - 1}], got {process_id!r}")
    jax.distributed.initialize(coordinator_address=coordinator, num_processes=int(num_processes),
                               process_id=int(process_id))


def agree(flag: bool) -> bool:
    """Process 0's ``flag``, in every process (the flag itself with one process)."""
    if jax.process_count() == 1:
        return bool(flag)
    from ._compat import broadcast_one_to_all

    return bool(broadcast_one_to_all(np.asarray(flag, dtype=np.int32)))


__all__ = ["agree", "initialize", "parse_address"]
