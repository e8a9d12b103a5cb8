"""Semi-smooth Newton loop and the convergence test of eq. 51.

Each sub-problem of a step supplies two pure functions:

``residual(x) -> Residual``
    the residual vector r at the iterate x, the right-hand side of the test
    (51) ``tol_r (sum_k ||r_k|| + tol_f)`` built from its terms r_k, and an
    ``aux`` pytree (active set, multipliers...) handed to ``update``;
``update(x, residual) -> (dx, floor)``
    the Newton correction from the iteration matrix, and the round-off floor
    of the residual at that iterate.

The floor exists because when every term of a residual is exactly zero in exact
arithmetic (rigid motion of an elastic body, a body at rest) the test (51)
falls to ``tol_r * tol_f``, below the round-off of an assembled stiff force
(about ``eps * ||K|| * ||q||``); Newton would then spin to the iteration cap on
a state that has converged.

The loop is ``lax.while_loop``: compute r, stop if it passes, else solve and
update (Algorithm 1, lines 11-19). Its iteration count is the number of linear
solves; it is 0 when the starting residual already passes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax

from .._custom_types import Scalar


class Residual(NamedTuple):
    r: jax.Array
    bound: Scalar
    aux: Any


class NewtonResult(eqx.Module):
    x: Any
    aux: Any
    iterations: jax.Array
    converged: jax.Array
    residual_norm: Scalar
    tolerance: Scalar


def convergence_bound(terms: list[jax.Array], tol_r: Scalar, tol_f: Scalar) -> Scalar:
    """Right-hand side of eq. 51: ``tol_r * (sum_k ||r_k|| + tol_f)``."""
    total = sum((jnp.linalg.norm(t) for t in terms), jnp.zeros(()))
    return tol_r * (total + tol_f)


def newton(
    residual: Callable[[Any], Residual],
    update: Callable[[Any, Residual], tuple[Any, Scalar]],
    x0: Any,
    max_iter: int | jax.Array,
    floor0: Scalar | None = None,
) -> NewtonResult:
    """Run Newton until eq. 51 holds (with the round-off floor) or ``max_iter``.

    A non-finite residual stops the loop at once and is reported as not converged.
    """
    res0 = residual(x0)
    floor0 = jnp.zeros((), res0.r.dtype) if floor0 is None else floor0

    def keep_going(carry):
        _, res, floor, it = carry
        norm = jnp.linalg.norm(res.r)
        return (norm >= res.bound + floor) & (it < max_iter) & jnp.isfinite(norm)

    def body(carry):
        x, res, _, it = carry
        dx, floor = update(x, res)
        x = jax.tree_util.tree_map(jnp.add, x, dx)
        return x, residual(x), floor, it + 1

    x, res, floor, it = lax.while_loop(keep_going, body, (x0, res0, floor0, jnp.zeros((), jnp.int32)))
    norm = jnp.linalg.norm(res.r)
    return NewtonResult(
        x=x,
        aux=res.aux,
        iterations=it,
        converged=(norm < res.bound + floor) & jnp.isfinite(norm),
        residual_norm=norm,
        tolerance=res.bound + floor,
    )


def _stop(tree):
    """stop_gradient on every floating-point array leaf (static values untouched)."""
    return jax.tree_util.tree_map(
        lambda a: lax.stop_gradient(a) if eqx.is_inexact_array(a) else a, tree
    )


def solve(builder, args: tuple, x0: Any, max_iter: int, differentiable: bool) -> NewtonResult:
    """Newton on the sub-problem ``builder(*args) -> (residual, update)``.

    With ``differentiable=False`` this is :func:`newton`. With ``True`` the
    Newton loop runs on stop-gradient copies of ``args`` (so no derivative ever
    enters the ``while_loop``, and reverse mode works), and the derivative of
    the converged solution x* comes from one more Newton correction built from
    the differentiable residual,

        x = x* + (dx - stop_gradient(dx)),   dx = -J(x*)^{-1} R(x*, θ),

    whose value is x* and whose derivative is -J^{-1} ∂R/∂θ: the implicit
    function theorem at x*, with the active set of x* frozen and J (built from
    the stop-gradient arguments) held fixed. Its accuracy follows the Newton
    tolerance, as x* does. The Newton iterations are never differentiated.
    """
    if not differentiable:
        residual, update = builder(*args)
        return newton(residual, update, x0, max_iter)
    residual_sg, update_sg = builder(*_stop(args))
    sol = newton(residual_sg, update_sg, _stop(x0), max_iter)
    residual, _ = builder(*args)
    x_star = sol.x
    res = residual(x_star)
    dx, _ = update_sg(x_star, res._replace(aux=_stop(res.aux)))
    x = jax.tree_util.tree_map(lambda a, d: a + (d - lax.stop_gradient(d)), x_star, dx)
    return eqx.tree_at(lambda s: (s.x, s.aux), sol, (x, residual(x).aux))
