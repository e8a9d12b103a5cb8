"""Type aliases used in signatures and docstrings.

Shapes: ``n`` generalised coordinates, ``nb`` bilateral constraints, ``nu``
unilateral constraints, ``nc = nb + nu`` constraints in all.
"""

from jaxtyping import Array, ArrayLike, Bool, Float, Int

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
