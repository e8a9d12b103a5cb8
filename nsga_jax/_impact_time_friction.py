"""The frictional impact law of the impact-time rebuild (:mod:`nsga_jax._impact_time`).

Where the model has frictional contacts, the rebuilt impact at the located
instant t_n + τ is Newton's law on the normal rows and Coulomb's law on the
tangential impulses of the frictional contacts in the impact, at impulse
level, with the mass matrix M and the rows G = [g_q; g_T] at q(τ):

    M (v⁺ - v⁻) = g_qᵀ P_N + g_Tᵀ P_T,
    g_q,j v⁺ = -e_j g_q,j v⁻                        (impact rows and joints),
    |P_T,j| <= μ_j P_N,j,  stick: γ_T,j⁺ = g_T,j v⁺ = 0,
                           slip:  P_T,j = -μ_j P_N,j γ_T,j⁺ / |γ_T,j⁺|,

the velocity jump's law (:mod:`~nsga_jax._integrators.friction`, Alart and
Curnier's projection on the disk D(μ P_N)) without the h f* term, its normal
rows equalities as in the frictionless rebuild. The value comes from a fixed
number of damped semi-smooth Newton iterations on stopped inputs; the
derivative from one more Newton correction at that solution with the inputs
live and the law's generalised Jacobian stopped, i.e. the implicit function
theorem with the stick/slip set of the solution frozen:
δ(v⁺ - v⁻) = -J⁻¹ ∂R/∂θ δθ.

After the impact the motion goes on with an acceleration a⁺ that keeps the
contacts that stay closed closed at acceleration level, with their friction
(:func:`continuation`): a contact still slipping after the impact
(|γ_T⁺| > 0) carries the sliding force -μ N γ_T⁺/|γ_T⁺| with the normal
force N it takes; one that sticks after the impact is held sticking (zero
tangential acceleration; the cone |F_T| <= μ N is not checked at
acceleration level, so a contact that would start to slip during the rest
of the step is held: a first-order error in the step's derivative only
where the friction force of a closed contact reaches the cone within h).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax

from ._custom_types import Vector
from ._integrators.contact_rows import velocity_rows
from ._integrators.friction import FrictionLaw
from ._integrators.linalg import Factorisation, dense_solve, masked_solve
from ._integrators.newton import damped_step
from ._models.base import Model

IMPACT_ITERATIONS = 12
"""Damped semi-smooth Newton iterations on the frictional impact (stopped)."""

STICK_TOLERANCE = 1e-9
"""A contact sticks after the impact where |γ_T⁺| <= this times (1 + |γ_T⁻|) [m/s]."""


def _law(model: Model, M: jax.Array, rows: jax.Array, in_impact: jax.Array) -> FrictionLaw:
    """The impact's contact law: equalities on the impact rows and joints
    (``unilateral`` all False), Coulomb on the tangents, with the scaling m̄
    and the contacts' own masses as tangential penalties (neither changes the
    solution)."""
    nc = model.n_constraints
    mbar = jnp.asarray(model.mbar, M.dtype)
    return FrictionLaw.of(model, in_impact, jnp.zeros((nc,), bool), mbar, mbar, jnp.diagonal(M), rows[nc:])


def frictional_impact(model: Model, M: jax.Array, G: jax.Array, q_hit: Vector, v_minus: Vector,
                      in_impact: jax.Array, e: jax.Array) -> Vector:
    """v⁺ after the frictional impact at q_hit (module docstring). ``G``: g_q
    (nc, n) at q_hit, ``in_impact`` the rows (nc,) the impact acts on,
    ``e`` the restitution over all rows (nc,)."""
    n = model.n_dof
    rows = velocity_rows(model, q_hit, G)
    restituted = jnp.concatenate([e * (G @ v_minus), jnp.zeros((rows.shape[0] - G.shape[0],), G.dtype)])
    law = _law(model, M, rows, in_impact)

    def residual_of(law, M, rows, v_minus, restituted):
        def residual(x):
            W, lam = x
            rate = rows @ (v_minus + W) + restituted
            return law.residual(M @ W, jnp.zeros_like(W), rows, rate, lam, 1.0, 1.0)
        return residual

    live = (law, M, rows, v_minus, restituted)
    law_s = law._replace(mu=lax.stop_gradient(law.mu), p_t=lax.stop_gradient(law.p_t),
                         k=lax.stop_gradient(law.k), p=lax.stop_gradient(law.p))
    M_s, rows_s, v_s, rest_s = (lax.stop_gradient(t) for t in live[1:])
    stopped = (law_s, M_s, rows_s, v_s, rest_s)
    residual_s = residual_of(*stopped)
    matrix = Factorisation.of(M_s, jnp.zeros((), M.dtype), jnp.zeros((), M.dtype))

    def correction(x, r):  # Newton's correction, linear in r, with the law's Jacobian at x (stopped)
        W, lam = x
        # (no bound: the compliant solve alone, never a pivot, so that it stays linear in r)
        return law_s.correction(matrix, r[:n], r[n:], rows_s, rows_s, lam, rows_s @ (v_s + W) + rest_s, None)

    def iteration(_, carry):
        x, res = carry
        return damped_step(residual_s, x, correction(x, res.r), res)

    x = (jnp.zeros_like(v_minus), jnp.zeros((rows.shape[0],), v_minus.dtype))
    x, _ = lax.fori_loop(0, IMPACT_ITERATIONS, iteration, (x, residual_s(x)))
    x = jax.tree_util.tree_map(lax.stop_gradient, x)
    # the implicit function step: value x* (to the iteration's residual), derivative -J⁻¹ ∂R/∂θ
    r = residual_of(*live)(x).r
    dW, _ = correction(x, r - lax.stop_gradient(r))
    return v_minus + x[0] + dW


def continuation(model: Model, M: jax.Array, G: jax.Array, q_hit: Vector, v_minus: Vector, v_plus: Vector,
                 a: Vector, closed: jax.Array) -> Vector:
    """a⁺: the acceleration a made to keep the rows ``closed`` (nc,: the
    joints and the contacts that stay closed) closed at acceleration level
    at (q_hit, v⁺), convective terms included, with the friction of the
    frictional contacts among them (module docstring): ``a⁺ = a + M⁻¹ Fᵀ f``,
    ``(R M⁻¹ Fᵀ)_A f_A = -(Ṙ v⁺ + R a)_A`` on the rows R =
    [g_q; g_T] of A = the closed normal rows and the tangents of the
    contacts that stick, with force directions F: g_q,j - μ_j t̂_jᵀ g_T,j for
    a closed contact that slips along t̂_j = γ_T⁺/|γ_T⁺|, the rows themselves
    otherwise."""
    nf, d, n = model.n_friction, model.friction_dim, model.n_dof
    rows = velocity_rows(model, q_hit, G)
    GT = rows[G.shape[0]:].reshape(nf, d, n)
    normals = jnp.asarray(model.friction_normals)
    mu = jnp.asarray(model.friction_coefficients, G.dtype)
    slip = jnp.einsum("jdn,n->jd", GT, v_plus)
    speed_sq = jnp.sum(slip * slip, axis=1)
    scale = 1.0 + jnp.linalg.norm(lax.stop_gradient(jnp.einsum("jdn,n->jd", GT, v_minus)), axis=1)
    touching = closed[normals]
    sticks = lax.stop_gradient(touching & (speed_sq <= (STICK_TOLERANCE * scale) ** 2))
    slides = touching & ~sticks
    # the norm taken only where the contact slides (|γ_T⁺| > 0 there): a sticking contact's
    # γ_T⁺ is often exactly 0, where the norm's derivative is 0/0 and the masked branch of a
    # jnp.where would still send NaN into the reverse pass (0 · ∞)
    speed = jnp.sqrt(jnp.where(slides, speed_sq, 1.0))
    direction = slip / speed[:, None]
    drag = jnp.einsum("jd,jdn->jn", jnp.where(slides, mu, 0.0)[:, None] * direction, GT)
    forces = rows.at[normals].add(-drag)
    active = jnp.concatenate([closed, jnp.repeat(sticks, d)])
    # the rows' convective rates (d/dt R) v⁺: the joints' and the closed contacts' curvature terms
    convective = jax.jvp(lambda x: velocity_rows(model, x, model.constraint_jacobian(x)) @ v_plus, (q_hit,),
                         (v_plus,))[1]
    Minv_Ft = dense_solve(M)(forces.T)
    f = masked_solve(rows @ Minv_Ft, -convective - rows @ a, active)
    return a + Minv_Ft @ f
