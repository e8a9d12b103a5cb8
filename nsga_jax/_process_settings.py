"""The process-wide settings nsga_jax runs best with, set only when asked.

Importing nsga_jax changes no JAX option and no environment variable. The
command line calls :func:`configure_jax` for its own process, and so may a
program, once, at its top:

- **JAX's 64-bit mode** (``jax_enable_x64``): runs are float64 by default,
  and a float64 run without the mode is refused by name;
- **XLA's concurrency-optimised CPU scheduler off**
  (:data:`CPU_SCHEDULER_FLAG` in ``XLA_FLAGS``): steps on a CPU measured
  faster without it (up to a quarter less time a step; the table and its
  script are in docs/performance.md, *XLA's CPU scheduler*). Environment
  variables are read when JAX starts its backend, so this takes effect only
  before JAX's first computation; a value of the flag already in
  ``XLA_FLAGS`` is the user's and is kept.
"""

from __future__ import annotations

import os
import sys

CPU_SCHEDULER_FLAG = "--xla_cpu_enable_concurrency_optimized_scheduler=false"
"""The XLA flag :func:`configure_jax` adds to ``XLA_FLAGS``."""


def configure_jax(*, float64: bool = True, cpu_flags: bool = True) -> None:
    """Turn on, for this process, what nsga_jax runs best with: JAX's 64-bit
    mode (``float64``) and the XLA CPU flag :data:`CPU_SCHEDULER_FLAG`
    (``cpu_flags``; only before JAX's first computation, and not where
    ``XLA_FLAGS`` already names the flag). JAX is not imported by this call
    when it is not yet loaded: the 64-bit mode is then set through
    ``JAX_ENABLE_X64``, which JAX reads when it loads."""
    if cpu_flags:
        name = CPU_SCHEDULER_FLAG.split("=")[0]
        flags = os.environ.get("XLA_FLAGS", "")
        if name not in flags:
            os.environ["XLA_FLAGS"] = f"{flags} {CPU_SCHEDULER_FLAG}".strip()
    if float64:
        if "jax" in sys.modules:
            sys.modules["jax"].config.update("jax_enable_x64", True)
        else:
            os.environ["JAX_ENABLE_X64"] = "1"


__all__ = ["CPU_SCHEDULER_FLAG", "configure_jax"]
