"""Models: the abstract :class:`Model` interface the integrators step.

Every built-in scene is a :class:`~nsga_jax.system.System` of parts compiled
into one :class:`~nsga_jax.system.SystemModel`; a model written by hand
implements :class:`Model` directly (docs/own-model.md) and is checked with
:func:`~nsga_jax._models.check.check_model`.
"""

from .base import Model
from .capabilities import ElementBlocks, EnergyMonitor, FrictionalContacts

__all__ = ["Model", "ElementBlocks", "EnergyMonitor", "FrictionalContacts"]
