"""Type aliases used in signatures and docstrings.

Shapes: ``n`` generalised coordinates, ``nb`` bilateral constraints, ``nu``
unilateral constraints, ``nc = nb + nu`` constraints in all.
"""

import os

import jax
from jaxtyping import Array, ArrayLike, Bool, Float, Int

# Every numerical module imports this one first: float64 is on from the moment
# they load (NSGA_JAX_X64=0 leaves JAX's setting alone; see nsga_jax/__init__.py).
if os.environ.get("NSGA_JAX_X64", "1").strip().lower() not in ("0", "false", "no", "off"):
    jax.config.update("jax_enable_x64", True)

Scalar = Float[Array, ""]
ScalarLike = float | Float[ArrayLike, ""]
Vector = Float[Array, " n"]
Matrix = Float[Array, "n n"]
ConstraintVector = Float[Array, " nc"]
ConstraintMatrix = Float[Array, "nc n"]
ActiveSet = Bool[Array, " nc"]
Iterations = Int[Array, ""]

__all__ = [
    "Array",
    "ArrayLike",
    "Scalar",
    "ScalarLike",
    "Vector",
    "Matrix",
    "ConstraintVector",
    "ConstraintMatrix",
    "ActiveSet",
    "Iterations",
]
