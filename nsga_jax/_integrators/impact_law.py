"""The impact law of the velocity jump: Newton's restitution (the default) or
the energetic law, which cannot create energy with friction and e > 0.

Newton's kinematic law, ġ_N⁺ = -e ġ_N⁻ on the contacts that take an impulse,
combined with Coulomb's friction on the slip at the end of the jump, can
*raise* the kinetic energy of an eccentric impact where the normal impulse
reverses the slip (Kane and Levinson's paradox, docs/friction.md). The
energetic law (``impact_law = "energetic"``, DS and DSn) solves the jump
twice with the same Alart–Curnier law,

- the **compression** jump (v_c, P_c): every e set to 0, which cannot create
  energy (its impulses do no positive work);
- **Newton's** jump (v_e, P_e): the contacts' own e;

and keeps the largest s ∈ [0, 1] for which the velocity and the impulses

    v(s) = (1 - s) v_c + s v_e,      P(s) = (1 - s) P_c + s P_e

release in restitution at most ē² of the kinetic energy absorbed in
compression (Stronge's energetic bound, ē the largest e of the contacts
that take an impulse in compression):

    T(v(s)) <= T_c + ē² (T⁻ - T_c),     T(v) = ½ vᵀ M(q) v,

where T⁻ = T(v⁻) and v⁻ = v_e - A⁻¹ Gᵀ P_e is the velocity the jump gives
without any contact impulse (A the jump's iteration matrix, M or M + h C).
As ē <= 1 the bound is at most T⁻: the impact cannot create energy. T(v(s))
is a convex quadratic in s with T(v(0)) = T_c below the bound, so s is the
larger root of ``T(v(s)) = bound`` in closed form, and s = 1 (Newton's jump,
exactly) wherever Newton's law keeps within the bound to the Newton
tolerance tol_r of T⁻ (the accuracy of the two solves): a frictionless
impact of one contact (or of several with one e) lies on the bound, so the
law is Newton's there.

v(s) satisfies everything that is linear in the jump: the momentum balance
(exactly for a linear A, e.g. a rigid body's constant mass), the bilateral
constraints, Newton's law with the effective coefficient s e on every
contact active in both jumps, ġ_N >= 0, and Coulomb's cone |P_T| <= μ P_N
(a convex set). Where both jumps stick, or both slide the same way, it is
Coulomb's law with s e exactly; where one sticks and the other slides, the
friction impulse is admissible but may lie inside the cone while the
contact slips (a projection on the dissipative set, not a re-solve).
The closed form is differentiable (the implicit derivatives of both solves,
then smooth algebra, with s = 1 or the root frozen at the switch).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Scalar, Vector
from .._models.base import Model
from .contact_rows import has_friction, velocity_rows
from .model_terms import restitution
from .newton import NewtonResult, solve
from .records import VelocityAux
from .subproblem_inputs import VelocityInputs
from .subproblems import velocity_problem


def energetic_applies(impact_law: str, model: Model) -> bool:
    """Whether a step takes the energetic law's two jumps (static): the law
    asked for, on a model with frictional contacts (without friction there is
    no paradox and the step is Newton's, traced as without the option)."""
    return impact_law == "energetic" and has_friction(model)


def contact_impulses(aux: VelocityAux) -> jax.Array:
    """The impulses P (nc + nf·d) [N s] of a converged velocity jump: the
    normal ones on the active set and the tangential ones below them."""
    P = jnp.where(aux.active, aux.multiplier, 0.0)
    return P if aux.friction is None else jnp.concatenate([P, aux.friction])


def restitution_share(s: Scalar, e_jump: NewtonResult, compression: NewtonResult) -> tuple[Vector, VelocityAux]:
    """The jump W(s) and its record (1 - s) compression + s Newton; s = 1
    gives Newton's jump bit for bit, s = 0 the compression jump."""
    mix = lambda a, b: (1.0 - s) * a + s * b  # noqa: E731
    c, e = compression.aux, e_jump.aux
    P_c, P_e = jnp.where(c.active, c.multiplier, 0.0), jnp.where(e.active, e.multiplier, 0.0)
    friction = None if e.friction is None else mix(c.friction, e.friction)
    aux = VelocityAux(c.active | e.active, mix(P_c, P_e), mix(c.rate, e.rate), friction)
    return mix(compression.x[0], e_jump.x[0]), aux


def energetic_share(model: Model, mass_product, q: Vector, v_tilde: Vector, free_velocity: Vector,
                    restitution: jax.Array, e_jump: NewtonResult, compression: NewtonResult,
                    slack: Scalar) -> Scalar:
    """The share s ∈ [0, 1] of Newton's jump the energetic law keeps (module
    docstring). ``free_velocity``: v⁻, the velocity without contact impulses;
    ``restitution`` (nc,): e per constraint row (0 on bilaterals);
    ``mass_product(q, x)``: M(q) x; ``slack``: the relative tolerance on T⁻."""
    v_c, v_e = v_tilde + compression.x[0], v_tilde + e_jump.x[0]
    kinetic = lambda a, b: 0.5 * a @ mass_product(q, b)  # noqa: E731
    T_minus, T_c, T_e = kinetic(free_velocity, free_velocity), kinetic(v_c, v_c), kinetic(v_e, v_e)
    nc = model.n_constraints
    pushed = contact_impulses(compression.aux)[:nc] > 0
    e2 = jnp.max(jnp.where(pushed, restitution**2, 0.0), initial=0.0)
    target = T_c + e2 * jnp.maximum(T_minus - T_c, 0.0)
    delta = v_e - v_c
    a = kinetic(delta, delta)
    b = 2.0 * kinetic(v_c, delta)  # T(v(s)) = T_c + b s + a s²
    c = jnp.minimum(T_c - target, 0.0)
    disc = b**2 - 4.0 * a * c  # >= b² >= 0
    root_disc = jnp.sqrt(jnp.where(disc > 0, disc, 1.0)) * (disc > 0)
    positive_b = b > 0
    denominator = jnp.where(positive_b, b + root_disc, 2.0 * a)
    numerator = jnp.where(positive_b, -2.0 * c, -b + root_disc)
    safe = denominator > 0
    root = jnp.where(safe, numerator / jnp.where(safe, denominator, 1.0), 1.0)
    newton = T_e <= target + slack * jnp.abs(T_minus)  # within the bound to the jumps' own accuracy
    return jnp.where(newton, 1.0, jnp.clip(root, 0.0, 1.0)).astype(v_c.dtype)


def velocity_jump(impact_law: str, inputs: VelocityInputs, start, max_iter: int, held, slack: Scalar
                  ) -> tuple[NewtonResult, Vector, VelocityAux]:
    """Step 3 under the scheme's impact law: ``(record, W, aux)``. ``inputs``
    are :func:`~nsga_jax._integrators.subproblems.velocity_problem`'s; Newton's
    law is its one solve, traced as it always was; the energetic law adds the
    compression jump (g_{q,n} v_n set to zero: every e = 0) and keeps the
    share of Newton's jump that :func:`energetic_share` allows."""
    sol = solve(velocity_problem, inputs, start, max_iter, held, name="velocity_jump")
    model, ops = inputs.model, inputs.ops
    if not energetic_applies(impact_law, model):
        return sol, sol.x[0], sol.aux
    smooth = inputs.smooth
    no_restitution = eqx.tree_at(lambda i: i.G_prev_v_prev, inputs, jnp.zeros_like(inputs.G_prev_v_prev))
    compression = solve(velocity_problem, no_restitution, start, max_iter, held, name="velocity_jump_compression")
    q = smooth.q + inputs.U
    problem = velocity_problem(inputs)
    A = problem.linearise(sol.x, problem.residual(sol.x))  # the jump's matrix, M or M + h C
    G = velocity_rows(model, q, ops.constraints.jacobian(model, q))
    free = smooth.v + sol.x[0] - A.solve(G.T @ contact_impulses(sol.aux))
    s = energetic_share(model, lambda y, x: ops.mass.product(model, y, x), q, smooth.v, free,
                        restitution(model, q.dtype), sol, compression, slack)
    W, aux = restitution_share(s, sol, compression)
    return merged_record(sol, compression), W, aux


def merged_record(e_jump: NewtonResult, compression: NewtonResult) -> NewtonResult:
    """One record of the two jumps: their iterations summed, converged when
    both are, the residual of the compression jump where it failed."""
    ok = compression.converged
    return NewtonResult(x=e_jump.x, aux=e_jump.aux, iterations=e_jump.iterations + compression.iterations,
                        converged=e_jump.converged & ok,
                        residual_norm=jnp.where(ok, e_jump.residual_norm, compression.residual_norm),
                        tolerance=jnp.where(ok, e_jump.tolerance, compression.tolerance),
                        factorisation=e_jump.factorisation)


__all__ = ["contact_impulses", "energetic_applies", "energetic_share",
           "merged_record", "restitution_share", "velocity_jump"]
