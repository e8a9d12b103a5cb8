"""Small helpers shared across modules."""

import jax
import jax.numpy as jnp


def as_float(x) -> jax.Array:
    """Field converter: numbers become float arrays, i.e. pytree leaves that
    ``jit`` traces (changing them never recompiles) and ``grad`` can reach."""
    return jnp.asarray(x, dtype=float)
