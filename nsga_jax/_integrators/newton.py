"""Semi-smooth Newton loop and the convergence test of eq. 51.

Each sub-problem of a step is a :class:`Problem` of three pure functions:

``residual(x) -> Residual``
    the residual vector r at the iterate x, the right-hand side of the test
    (51) ``tol_r (sum_k ||r_k|| + tol_f)`` built from its terms r_k, and an
    ``aux`` pytree (active set, multipliers...) handed to the two others;
``linearise(x, residual) -> J``
    the iteration matrix at x, ready to solve with: a fresh LU factorisation
    (the expensive part: tangents and the factorisation), or the precomputed
    matrix itself where it is constant
    (:mod:`~nsga_jax._integrators.iteration_matrix`);
``correct(x, residual, J) -> (dx, floor)``
    the Newton correction solved with J, and the round-off floor of the
    residual at that iterate.

The floor exists because when every term of a residual is exactly zero in exact
arithmetic (rigid motion of an elastic body, a body at rest) the test (51)
falls to ``tol_r * tol_f``, below the round-off of an assembled stiff force
(about ``eps * ||K|| * ||q||``); Newton would then spin to the iteration cap on
a state that has converged.

The loop is ``lax.while_loop``: compute r, stop if it passes, else solve and
update (Algorithm 1, lines 11-19). Its iteration count is the number of linear
solves; it is 0 when the starting residual already passes.

Given a :class:`~nsga_jax._integrators.linalg.Factorisation` to start from,
the loop is a *modified* Newton method that factors only when needed: it
solves with the factorisation it holds (from an earlier iteration or step)
and refactors at the current iterate when it holds none, or when an update
made with it did not shrink the residual by :data:`CONTRACTION` (that update
is then discarded). A fresh factorisation's update is always taken, as in
Newton's method, so the iteration is never worse than Newton's; at small
steps, where the matrix changes little, most iterations are one residual and
one pair of triangular solves. In a batch (``vmap``) the members refactor
together, and only when one of them needs it (:func:`where_needed`).

The schemes call :func:`solve`: :func:`newton` under a profile scope named for
the sub-problem (Algorithm 1's smooth motion, position correction and
velocity jump), with the implicit derivative of the converged solution as a
custom JVP, so that every step is differentiable and a step that nobody
differentiates is the Newton loop alone.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax

from .._custom_types import Scalar
from .linalg import Factorisation

CONTRACTION = 0.1
"""A held factorisation is kept while each of its updates divides the residual
norm by at least 1/CONTRACTION (or reaches the tolerance)."""


class Residual(NamedTuple):
    r: jax.Array
    bound: Scalar
    aux: Any


LINE_SEARCH_HALVINGS = 6
"""The most halvings of a damped Newton update (:func:`damped_step`)."""


class Problem(NamedTuple):
    """The three functions of a Newton sub-problem (see the module docstring).
    ``line_search`` (static): damp each update until the residual norm
    decreases (:func:`damped_step`), for residuals whose semi-smooth Newton
    may cycle (Coulomb friction's projection on a disk). ``restart(factor)``:
    the same sub-problem written another way for each factor (the same
    solution, another Newton path; ``restart(1.0)`` is the problem itself),
    run from the start with each of ``restart_factors`` in turn while Newton
    stalls (:func:`newton`), or ``None``."""

    residual: Callable[[Any], Residual]
    linearise: Callable[[Any, Residual], Any]
    correct: Callable[[Any, Residual, Any], tuple[Any, Scalar]]
    line_search: bool = False
    restart: Callable[[jax.Array], "Problem"] | None = None
    restart_factors: tuple[float, ...] = ()

    def update(self, x, res: Residual) -> tuple[Any, Scalar]:
        """The Newton correction with the iteration matrix at x."""
        return self.correct(x, res, self.linearise(x, res))

    def advance(self, x, dx, res: Residual) -> tuple[Any, Residual]:
        """``x + dx`` and its residual, damped by :func:`damped_step` when
        ``line_search`` is set (``res`` is the residual at x)."""
        if self.line_search:
            return damped_step(self.residual, x, dx, res)
        x_new = jax.tree_util.tree_map(jnp.add, x, dx)
        return x_new, self.residual(x_new)

    @classmethod
    def from_update(cls, residual, update, line_search: bool = False) -> "Problem":
        """A problem whose correction always builds its own matrix (no reuse)."""
        return cls(residual, lambda x, res: None, lambda x, res, _: update(x, res), line_search)


def damped_step(residual: Callable[[Any], Residual], x, dx, res: Residual) -> tuple[Any, Residual]:
    """``x + α dx`` with α = 1, 1/2, 1/4, ... (at most
    :data:`LINE_SEARCH_HALVINGS` halvings): the first that decreases the
    residual norm by the Armijo factor 1 - 1e-4 α. A full Newton step that
    decreases the norm is taken as it is, so where Newton converges the
    iterates are Newton's. When no α decreases the norm, the full step is
    taken if it raises the norm by at most :data:`ALLOWED_GROWTH` (a step
    that changes the law's active set on purpose: a sticking contact of a
    redundant set moved to slide, :meth:`~nsga_jax._integrators.friction.FrictionLaw.first_slip`,
    whose residual is flat in α until the contact slides), else the shortest."""
    norm = jnp.linalg.norm(res.r)

    def trial(alpha):
        x_new = jax.tree_util.tree_map(lambda a, b: a + alpha * b, x, dx)
        return x_new, residual(x_new)

    def too_long(carry):
        alpha, (_, res_new), k = carry
        return (~(jnp.linalg.norm(res_new.r) <= (1.0 - 1e-4 * alpha) * norm)) & (k < LINE_SEARCH_HALVINGS)

    def halve(carry):
        alpha, _, k = carry
        return alpha / 2, trial(alpha / 2), k + 1

    one = jnp.ones((), norm.dtype)
    full = trial(one)
    alpha, last, _ = lax.while_loop(too_long, halve, (one, full, jnp.zeros((), jnp.int32)))
    decreased = jnp.linalg.norm(last[1].r) <= (1.0 - 1e-4 * alpha) * norm
    take_full = ~decreased & (jnp.linalg.norm(full[1].r) <= ALLOWED_GROWTH * norm)
    return jax.tree_util.tree_map(lambda a, b: jnp.where(take_full, a, b), full, last)


ALLOWED_GROWTH = 10.0
"""The most a full Newton step may raise the residual norm and still be taken
by :func:`damped_step` when no shorter one decreases it; a step that raises it
by orders of magnitude is a cycle of the semi-smooth iteration, never taken."""


class NewtonResult(eqx.Module):
    x: Any
    aux: Any
    iterations: jax.Array
    converged: jax.Array
    residual_norm: Scalar
    tolerance: Scalar
    factorisation: Factorisation | None = None


@jax.custom_batching.custom_vmap
def any_member(pred: jax.Array) -> jax.Array:
    """``pred`` (a bool scalar), and under ``vmap`` whether it holds for any
    member, as one unbatched value."""
    return pred


@any_member.def_vmap
def _any_member_rule(axis_size, in_batched, pred):
    return (jnp.any(pred) if in_batched[0] else pred), False


def where_needed(pred: jax.Array, fn: Callable[[], Any], otherwise: Any) -> Any:
    """``fn()`` if ``pred`` else ``otherwise`` (a pytree shaped as fn's result),
    evaluating ``fn`` only when needed, also under ``vmap``.

    ``lax.cond`` with a batched predicate becomes a select of both branches, so
    every member of a batch would refactor at every iteration. Here the branch
    is taken when ``pred`` holds for any member (:func:`any_member`, unbatched,
    so the ``cond`` stays one), and its result kept where ``pred`` holds.
    """

    def needed():
        return jax.tree_util.tree_map(lambda a, b: jnp.where(pred, a, b), fn(), otherwise)

    return lax.cond(any_member(pred), needed, lambda: otherwise)


def convergence_bound(terms: list[jax.Array], tol_r: Scalar, tol_f: Scalar) -> Scalar:
    """Right-hand side of eq. 51: ``tol_r * (sum_k ||r_k|| + tol_f)``."""
    total = sum((jnp.linalg.norm(t) for t in terms), jnp.zeros((), jnp.result_type(*terms, float)))
    return tol_r * (total + tol_f)


def newton(
    problem: Problem,
    x0: Any,
    max_iter: int | jax.Array,
    factorisation: Factorisation | None = None,
) -> NewtonResult:
    """Run Newton until eq. 51 holds (with the round-off floor) or ``max_iter``.

    With a ``factorisation`` (possibly the empty placeholder) the loop is the
    modified Newton method of the module docstring, and the result carries the
    factorisation it ends with. A non-finite residual stops the loop at once
    and is reported as not converged. A problem with ``restart_factors`` that
    has not converged is run again from ``x0`` as ``restart(factor)`` for each
    factor in turn (up to ``max_iter`` more iterations each, counted in the
    result). The runs are one Newton loop in a ``lax.while_loop`` over the
    factors (1 first), so the loop is compiled once, and a step that converges
    runs it once.
    """
    if problem.restart is None or not problem.restart_factors:
        return _newton_loop(problem, x0, max_iter, factorisation)
    real = jax.tree_util.tree_leaves(x0)[0].dtype
    factors = jnp.asarray((1.0, *problem.restart_factors), real)

    def attempt(k):
        return _newton_loop(problem.restart(factors[k]), x0, max_iter, factorisation)

    def stalled(carry):
        k, result = carry
        return ~result.converged & (k < factors.shape[0])

    def again(carry):
        k, result = carry
        new = attempt(k)
        return k + 1, dataclasses.replace(new, iterations=result.iterations + new.iterations)

    shapes = jax.eval_shape(lambda: attempt(0))
    nothing = jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), shapes)  # converged False, 0 iterations
    return lax.while_loop(stalled, again, (jnp.zeros((), jnp.int32), nothing))[1]


def _newton_loop(problem: Problem, x0: Any, max_iter: int | jax.Array,
                 factorisation: Factorisation | None) -> NewtonResult:
    """One Newton run of :func:`newton` (its ``restart`` aside)."""
    residual = problem.residual
    res0 = residual(x0)
    floor0 = jnp.zeros((), res0.r.dtype)

    def keep_going(carry):
        _, res, floor, it = carry[:4]
        norm = jnp.linalg.norm(res.r)
        return (norm >= res.bound + floor) & (it < max_iter) & jnp.isfinite(norm)

    def keep_going_reusing(carry):
        _, res, floor, it, _, refactor, margin = carry
        norm = jnp.linalg.norm(res.r)
        tolerance = res.bound + floor
        # an iterate that passes eq. 51 but not the margin is final once the held
        # factorisation stops contracting (refactor set; the residual is then at
        # round-off), rather than refactoring to improve a converged iterate
        done = (norm < margin * tolerance) | (refactor & (norm < tolerance))
        return ~done & (it < max_iter) & jnp.isfinite(norm)

    def body(carry):
        x, res, _, it = carry
        dx, floor = problem.update(x, res)
        x, res = problem.advance(x, dx, res)
        return x, res, floor, it + 1

    def body_reusing(carry):
        x, res, floor, it, held, refactor, margin = carry
        held = where_needed(refactor, lambda: problem.linearise(x, res), held)
        dx, new_floor = problem.correct(x, res, held)
        x_new, res_new = problem.advance(x, dx, res)
        # an iterate of a held factorisation must pass the test with a margin: it
        # converges linearly, where Newton's last iterate lands far below the test
        new_margin = jnp.where(refactor, 1.0, CONTRACTION).astype(floor.dtype)
        norm, norm_new = jnp.linalg.norm(res.r), jnp.linalg.norm(res_new.r)
        contracted = (norm_new <= CONTRACTION * norm) | (norm_new < new_margin * (res_new.bound + new_floor))
        take = contracted | refactor
        x, res, floor, margin = jax.tree_util.tree_map(
            lambda a, b: jnp.where(take, a, b), (x_new, res_new, new_floor, new_margin), (x, res, floor, margin))
        return x, res, floor, it + 1, held, ~contracted, margin

    zero = jnp.zeros((), jnp.int32)
    if factorisation is None:
        x, res, floor, it = lax.while_loop(keep_going, body, (x0, res0, floor0, zero))
    else:
        carry = (x0, res0, floor0, zero, factorisation, ~factorisation.valid, jnp.ones((), floor0.dtype))
        x, res, floor, it, factorisation, _, _ = lax.while_loop(keep_going_reusing, body_reusing, carry)
    norm = jnp.linalg.norm(res.r)
    return NewtonResult(
        x=x,
        aux=res.aux,
        iterations=it,
        converged=(norm < res.bound + floor) & jnp.isfinite(norm),
        residual_norm=norm,
        tolerance=res.bound + floor,
        factorisation=factorisation,
    )


def solve(builder: Callable[[Any], Problem], inputs: Any, x0: Any, max_iter: int,
          factorisation: Factorisation | None = None, name: str = "newton") -> NewtonResult:
    """Newton on the sub-problem ``builder(inputs) -> Problem``, modified Newton
    from ``factorisation`` when one is given: :func:`newton`, under the profile
    scope ``name``, with the implicit derivative of its converged solution.

    ``builder`` must close over no arrays: everything the problem depends on
    is in ``inputs``, a pytree (a sub-problem's named inputs,
    :mod:`~nsga_jax._integrators.subproblem_inputs`), whose floating-point
    arrays are what the derivative is taken with respect to. The primal is :func:`newton` alone. Differentiated
    (``jax.jvp``, ``jax.grad``, ``jax.vmap`` of either), the solution x* of
    R(x, θ) = 0 (θ: the arrays of ``inputs``) has the tangent of the implicit
    function theorem,

        dx = -J(x*)⁻¹ (∂R/∂θ · dθ),

    with the active set of x* frozen and J the iteration matrix rebuilt at x*
    (never a held factorisation); the residual's ``aux`` (multipliers, gaps)
    follows x* and θ. The Newton iterations are never differentiated; the
    starting point, the held factorisation and the counters get zero tangents.
    The accuracy of dx follows the Newton tolerance, as x* does.
    """
    with jax.named_scope(name):
        return _implicit_newton(builder, inputs, x0, factorisation, max_iter=max_iter)


@eqx.filter_custom_jvp
def _implicit_newton(builder, inputs, x0, factorisation, *, max_iter):
    return newton(builder(inputs), x0, max_iter, factorisation)


def _is_none(x) -> bool:
    return x is None


@_implicit_newton.def_jvp
def _implicit_newton_jvp(primals, tangents, *, max_iter):
    """The converged solution and its tangent of the implicit function theorem
    (see :func:`solve`), linear in the tangents of ``inputs`` and transposable."""
    builder, inputs, x0, factorisation = primals
    t_inputs = tangents[1]
    sol = _implicit_newton(builder, inputs, x0, factorisation, max_iter=max_iter)
    no_tangent = jax.tree_util.tree_map(_is_none, t_inputs, is_leaf=_is_none)
    nondiff, diff = eqx.partition(inputs, no_tangent, is_leaf=_is_none)

    def residual_at(d, x):
        return builder(eqx.combine(d, nondiff)).residual(x)

    x_star = sol.x
    res = residual_at(diff, x_star)
    # ∂R/∂θ · dθ at x*, and the correction -J(x*)⁻¹ applied to it (linear in its
    # right-hand side, so its jvp is the linear map itself)
    _, t_r = jax.jvp(lambda d: residual_at(d, x_star).r, (diff,), (t_inputs,))
    problem = builder(inputs)
    # (a zero bound: an iterative linear solve gives its tightest tolerance to the tangent)
    zero_bound = jnp.zeros_like(res.bound)
    _, (t_x, _) = jax.jvp(lambda r: problem.update(x_star, res._replace(r=r, bound=zero_bound)), (res.r,), (t_r,))
    _, t_aux = eqx.filter_jvp(lambda d, x: residual_at(d, x).aux, (diff, x_star), (t_inputs, t_x))
    t_sol = NewtonResult(x=t_x, aux=t_aux, iterations=None, converged=None, residual_norm=None, tolerance=None,
                         factorisation=jax.tree_util.tree_map(lambda _: None, sol.factorisation))
    return sol, t_sol
