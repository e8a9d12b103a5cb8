"""The time-stepping schemes and what they share (see docs/architecture.md)."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .base import AbstractScheme


def scheme_class(name: str) -> type[AbstractScheme]:
    """The scheme class called ``name`` in configs and on the command line
    (one of :data:`nsga_jax._validation.SCHEME_NAMES`); its ``name`` attribute
    is that name."""
    from .cs import CS
    from .ds import DS, DSn
    from .mj import MJ

    classes: dict[str, type[AbstractScheme]] = {cls.name: cls for cls in (DS, DSn, CS, MJ)}
    return classes[name]
