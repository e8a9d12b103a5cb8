"""The precision of a run: float64 (the default) or float32, taken from its inputs.

A run computes in the precision of what it is given: :func:`cast_floats` casts
the model's and the scheme's floating-point leaves, and the callers cast q0, v0,
h and t0, to the run's dtype; every array the schemes and models create takes
its dtype from these (``q.dtype``, ``h.dtype``, a leaf's dtype) or is a Python
number (weakly typed). A float32 run never touches JAX's configuration nor clears
its caches: its programs are cached like any other, keyed on the float32
shapes of their arguments. A float64 run needs JAX's 64-bit mode
(``jax_enable_x64``), which the caller turns on: :func:`require_x64_for`
refuses one without it, by name, before anything is traced.
"""

from __future__ import annotations

import warnings
from typing import TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._compat import jax_option
from ._results import ConfigError

DTYPES = ("float64", "float32")


X64_CALL = ('call nsga_jax.configure_jax() (or jax.config.update("jax_enable_x64", True)) at the top of the '
            'program, before building models (or set JAX_ENABLE_X64=1)')


def x64_enabled() -> bool:
    """Whether JAX's 64-bit mode is on (nsga_jax never turns it on itself)."""
    return bool(jax_option("jax_enable_x64"))


def require_x64_for(dtype: str) -> None:
    """Refuse a float64 run while JAX's 64-bit mode is off: JAX would then
    make its arrays float32, and the run would not be what was asked."""
    if dtype == "float64" and not x64_enabled():
        raise ConfigError(f'dtype="float64" (the default) needs JAX\'s 64-bit mode, which is off: '
                          f'{X64_CALL}; or run with dtype="float32"')


def require_x64(what: str) -> None:
    """Refuse ``what``, a computation made for float64 only (tolerances of
    1e-8 relative), while JAX's 64-bit mode is off: its float32 arrays
    would give a verdict that means nothing."""
    if not x64_enabled():
        raise ConfigError(f"{what} computes in float64 and needs JAX's 64-bit mode, which is off: {X64_CALL}")


def require_x64_for_inputs(**inputs) -> None:
    """Refuse float64 inputs (NumPy arrays, Python lists) while JAX's 64-bit
    mode is off, naming the first: JAX would silently round them to float32.
    JAX arrays and tracers carry their own precision and pass."""
    if x64_enabled():
        return
    for name, value in inputs.items():
        if isinstance(value, jax.Array) or value is None:
            continue
        if np.asarray(value).dtype == np.float64:
            raise ConfigError(f"{name} is float64 but JAX's 64-bit mode is off, so it would be rounded to float32: "
                              f"{X64_CALL}, or pass float32 arrays")


class PrecisionWarning(UserWarning):
    """A run whose precision cannot give what its model asks for (float32
    with Coulomb friction: sticking contacts creep)."""


FLOAT32_FRICTION = ("float32 with Coulomb friction: a sticking contact may creep, since the position "
                    "correction accepts a slip of the round-off of the gaps (64 eps of the coordinates) a step; "
                    "a stack of three boxes at rest moves 0.6 mm (planar) and 1.6 mm (3D) in 1 s at h = 1e-3 s, "
                    "against 5e-8 m without friction. Use float64 for bodies that rest or stick on "
                    "frictional contacts")


def precision_notes(model, dtype: str, stacklevel: int = 3) -> list[str]:
    """What ``dtype`` cannot give ``model``, warned (:class:`PrecisionWarning`)
    before the run and returned for its ``warnings``; ``[]`` when nothing."""
    if dtype != "float32" or model.n_friction == 0:
        return []
    warnings.warn(FLOAT32_FRICTION, PrecisionWarning, stacklevel=stacklevel)
    return [FLOAT32_FRICTION]


def refuse_mixed_precision(model, scheme, dtype: str) -> None:
    """Refuse float32 states with a model or scheme whose floating-point
    parameters are float64 (``integrate`` takes all three as given; the
    step would mix the two precisions and fail inside its loop), naming the
    first such parameter and the cast that fixes it. With JAX's 64-bit mode
    off every operation is float32 whatever the leaves hold, and nothing mixes."""
    if dtype != "float32" or not x64_enabled():
        return
    for owner, tree in (("model", model), ("scheme", scheme)):
        leaves = jax.tree_util.tree_leaves_with_path(tree)
        for path, leaf in leaves:
            if eqx.is_inexact_array(leaf) and leaf.dtype == jnp.float64:
                raise ConfigError(f"q0 and v0 are float32 but the {owner}'s parameter "
                                  f"{owner}{jax.tree_util.keystr(path)} is float64: cast both with "
                                  f'nsga_jax.cast_floats((model, scheme), "float32"), or run '
                                  f'simulate(..., dtype="float32"), which casts them')


_Tree = TypeVar("_Tree")


def cast_floats(tree: _Tree, dtype: str) -> _Tree:
    """Every floating-point leaf of ``tree`` (arrays and NumPy scalars) as ``dtype``."""

    def cast(x):
        return jnp.asarray(x, dtype) if eqx.is_inexact_array(x) or isinstance(x, np.floating) else x

    return jax.tree_util.tree_map(cast, tree)
