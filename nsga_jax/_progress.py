"""The progress a host-driven run shows on stderr: a line while it compiles,
then after each compiled chunk the steps done, the simulated time, the
measured time a step and the time left at that rate.

A large model's first output therefore comes after its compilation and one
chunk (:func:`~nsga_jax._chunks.chunk_length` keeps a large model's
chunks short: four steps of the 40-division cube), never after a silent
wait of minutes (docs/performance.md, "The first minute of a large run"); a
dense model whose first step is estimated long
(:func:`~nsga_jax._first_step.check_first_step`) says so on the compiling
line and runs its first chunk as a single step; after it a chunk holds
no more steps than :data:`EVERY_SECONDS` take at the measured rate
(:meth:`Progress.next_chunk`).
"""

from __future__ import annotations

import sys
import time

EVERY_SECONDS = 10.0
"""A chunk holds no more steps than this many seconds take at the rate
measured so far (one at least), so a slow run shows progress, and writes
its chunk files, about this often."""


def duration(seconds: float) -> str:
    """``seconds`` as ``12 s``, ``3.5 min`` or ``5.1 h``."""
    if seconds < 90:
        return f"{seconds:.3g} s"
    return f"{seconds / 60:.3g} min" if seconds < 5400 else f"{seconds / 3600:.3g} h"


class Progress:
    """Progress lines of a run of ``n_steps`` steps of size ``h`` from ``t0``
    (nothing printed where ``enabled`` is false), at most twice a second."""

    def __init__(self, n_steps: int, t0: float, h: float, enabled: bool):
        self.n_steps, self.t0, self.h, self.enabled = n_steps, t0, h, enabled
        self.shown = self.started = time.perf_counter()
        self.steps_done, self.long_first = 0, False

    def compiling(self, n_dof: int, estimate: str | None = None) -> float:
        """Say that the step is compiling, with the first step's ``estimate``
        where it is long; returns the time it started."""
        self.long_first = bool(estimate)
        if self.enabled:
            first = f"; first step estimated at {estimate}" if estimate else ""
            print(f"  compiling the step ({n_dof:,} coordinates{first}) ...", end="", file=sys.stderr, flush=True)
        return time.perf_counter()

    def compiled(self, started: float, source: str) -> None:
        """Say how long compiling took and, where not ``"compiled"``, how the programs were obtained."""
        if self.enabled:
            how = "" if source == "compiled" else f" ({source})"
            print(f" {time.perf_counter() - started:.1f} s{how}", file=sys.stderr, flush=True)
        self.shown = 0.0  # the first chunk is shown at once
        self.started = time.perf_counter()  # the steps' time, the host's work on each chunk included

    def next_chunk(self) -> int:
        """The most steps the next chunk should hold: one after a long
        estimate of the first step, else those of :data:`EVERY_SECONDS` at the
        rate measured so far (the chunk length caps it)."""
        if not self.steps_done:
            return 1 if self.long_first else 2**31 - 1
        rate = (time.perf_counter() - self.started) / self.steps_done
        return int(min(2**31 - 1, EVERY_SECONDS / max(rate, 1e-9)))

    def chunk(self, steps_done: int, last: bool) -> None:
        """After a chunk, with ``steps_done`` steps done since :meth:`compiled`."""
        self.steps_done = steps_done
        if not self.enabled or not (last or time.perf_counter() - self.shown > 0.5):
            return
        self.shown = time.perf_counter()
        rate = (self.shown - self.started) / max(steps_done, 1)
        left = "" if last else f", {duration(rate * (self.n_steps - steps_done))} left"
        print(f"\r  step {steps_done}/{self.n_steps} ({100.0 * steps_done / self.n_steps:5.1f} %), "
              f"t = {self.t0 + steps_done * self.h:.6g} s, {duration(rate)} a step{left}  ",
              end="\n" if last else "", file=sys.stderr, flush=True)
