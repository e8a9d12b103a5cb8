"""Element models: pure JAX functions of element coordinates and parameters."""

from .bar import bar_consistent_mass, bar_internal_force, bar_lumped_mass

__all__ = ["bar_internal_force", "bar_consistent_mass", "bar_lumped_mass"]
