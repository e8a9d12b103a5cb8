"""The precision of a run: float64 (the default) or float32, set for the enclosed code."""

from __future__ import annotations

import contextlib
from typing import TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

DTYPES = ("float64", "float32")


@contextlib.contextmanager
def precision(dtype: str):
    """Run the enclosed JAX code in ``dtype`` ("float64" or "float32").

    float32 turns ``jax_enable_x64`` off for the enclosed code and clears JAX's
    caches on entry and on exit: JAX caches the constants a traced function
    closes over (NumPy arrays) without their precision, so a function traced in
    one precision would otherwise be lowered with the other's constants. A
    float32 run therefore compiles afresh each time.
    """
    # JAX's Config defines its options as attributes at run time: none is declared to mypy
    if dtype == "float64" and jax.config.jax_enable_x64:  # type: ignore[attr-defined]
        yield
        return
    jax.clear_caches()
    try:
        with jax.enable_x64(dtype == "float64"):
            yield
    finally:
        jax.clear_caches()


_Tree = TypeVar("_Tree")


def cast_floats(tree: _Tree, dtype: str) -> _Tree:
    """Every floating-point leaf of ``tree`` (arrays and NumPy scalars) as ``dtype``."""

    def cast(x):
        return jnp.asarray(x, dtype) if eqx.is_inexact_array(x) or isinstance(x, np.floating) else x

    return jax.tree_util.tree_map(cast, tree)


