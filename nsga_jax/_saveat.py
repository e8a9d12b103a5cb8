"""What a run keeps: :class:`SaveAt`, the output control of
:func:`~nsga_jax.integrate` and :func:`~nsga_jax.simulate`.

One Module for every way of choosing the output (diffrax's ``SaveAt`` is the
model): every k-th step (``every``), a function of each step's state and
record instead of the full record (``fn``), and, for the host driver only,
the folder the kept steps are written to as the run goes (``chunks``).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import equinox as eqx

from ._integrators.base import StepState
from ._integrators.records import StepOutput
from ._results import ConfigError
from ._validation import describe, integer

SaveFn = Callable[[StepState, StepOutput], Any]
"""``(state, record) -> pytree``: what :class:`SaveAt` keeps of each step."""


class SaveAt(eqx.Module):
    """Which steps a run keeps, and what of them.

    Attributes:
        every: keep the records of every k-th step (step numbers 0, k, 2k,
            ...) and of the last step; the statistics (``Solution.stats``,
            ``failed_steps``) still cover every step. ``every = 1`` keeps all
            N + 1 rows; a long run with a large ``every`` holds flat memory
            under :func:`~nsga_jax.simulate`.
        fn: ``(state, record) -> pytree`` evaluated on the initial state and
            after each kept step, stacked along a leading axis of the kept
            rows in ``Solution.records`` in place of the full
            :class:`~nsga_jax.StepOutput` (``Solution.q`` and ``v`` are then
            empty, shape (0, n)): keep only what a loss needs under
            ``jax.grad``. Only :func:`~nsga_jax.integrate` honours it.
        chunks: a folder into which :func:`~nsga_jax.simulate` writes the
            kept steps (those of ``every``) as the run goes, in a few files
            ``chunk_XXXXX.npz`` (:class:`nsga_jax._chunks.RecordFiles`: at the
            latest every 10 s, and at once when the run stops or is
            interrupted; :func:`nsga_jax._chunks.load_chunks` reads them
            back), so an interrupted run loses nothing already computed. Only
            the host driver honours it.

    All fields are static (trace-time structure): a new ``SaveAt`` compiles a
    new program.
    """

    every: int = eqx.field(default=1, static=True)
    fn: SaveFn | None = eqx.field(default=None, static=True)
    chunks: str | Path | None = eqx.field(default=None, static=True)

    def __check_init__(self):
        try:  # the name users know from configurations and the command line, with the field
            integer("record_every", self.every, 1)
        except ConfigError as error:
            raise ConfigError(f"{error} (SaveAt.every: keep every k-th step and the last)") from None
        if self.fn is not None and not callable(self.fn):
            raise TypeError(f"SaveAt.fn must be a function (state, record) -> pytree or None, "
                            f"got {describe(self.fn)}")
        if self.chunks is not None and not isinstance(self.chunks, (str, Path)):
            raise TypeError(f"SaveAt.chunks must be a folder (str or pathlib.Path) or None, "
                            f"got {describe(self.chunks)}")

    def kept_steps(self, n_steps: int) -> list[int]:
        """The step numbers kept of a run of ``n_steps`` steps: 0, every k-th
        step and the last (Python integers, known at trace time)."""
        k = self.every
        return [0, *range(k, n_steps + 1, k)] + ([n_steps] if n_steps % k else [])


HOST_ONLY = ("chunks",)
"""The :class:`SaveAt` fields only the host driver :func:`~nsga_jax.simulate` honours."""

DEVICE_ONLY = ("fn",)
"""The :class:`SaveAt` fields only the pure :func:`~nsga_jax.integrate` honours."""


def refuse(saveat: SaveAt, fields: tuple[str, ...], caller: str, other: str) -> None:
    """Raise :class:`ConfigError` naming each of ``fields`` that ``saveat`` sets:
    ``caller`` cannot honour them, ``other`` can."""
    if not isinstance(saveat, SaveAt):
        raise TypeError(f"saveat must be a nsga_jax.SaveAt, got {describe(saveat)}")
    used = [name for name in fields if getattr(saveat, name) is not None]
    if used:
        raise ConfigError(f"{caller} cannot honour SaveAt.{', SaveAt.'.join(used)} "
                          f"(set to {', '.join(repr(getattr(saveat, n)) for n in used)}); use {other}")
