"""The precision of a run: float64 (the default) or float32, taken from its inputs.

A run computes in the precision of what it is given: :func:`cast_floats` casts
the model's and the scheme's floating-point leaves, and the callers cast q0, v0,
h and t0, to the run's dtype; every array the schemes and models create takes
its dtype from these (``q.dtype``, ``h.dtype``, a leaf's dtype) or is a Python
number (weakly typed). ``jax_enable_x64`` stays on throughout, so a float32 run
neither changes JAX's configuration nor clears its caches: its programs are
cached like any other, keyed on the float32 shapes of their arguments.
"""

from __future__ import annotations

from typing import TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .results import ConfigError

DTYPES = ("float64", "float32")


def require_x64_for(dtype: str) -> None:
    """Refuse a float64 run while ``jax_enable_x64`` is off (set so by the
    caller or ``NSGA_JAX_X64=0``): JAX would then make its arrays float32."""
    # JAX's Config defines its options as attributes at run time: none is declared to mypy
    if dtype == "float64" and not jax.config.jax_enable_x64:  # type: ignore[attr-defined]
        raise ConfigError('dtype="float64" needs jax_enable_x64 on (jax.config.update("jax_enable_x64", True)); '
                          'or run with dtype="float32"')


_Tree = TypeVar("_Tree")


def cast_floats(tree: _Tree, dtype: str) -> _Tree:
    """Every floating-point leaf of ``tree`` (arrays and NumPy scalars) as ``dtype``."""

    def cast(x):
        return jnp.asarray(x, dtype) if eqx.is_inexact_array(x) or isinstance(x, np.floating) else x

    return jax.tree_util.tree_map(cast, tree)
