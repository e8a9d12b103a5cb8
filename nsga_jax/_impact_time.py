"""Impact-time sensitivity: the derivative of an impact step in continuous time.

A time-stepping scheme puts every impact on the step grid. Its exact
derivative (what :func:`~nsga_jax.integrate` returns with
``adjoint=DiscreteAdjoint()``) therefore holds each impact at its step while a
parameter moves: it misses how the impact *instant* moves, which in continuous
time changes the state after the impact by the saltation term
``-(F⁺ - J F⁻) δt*`` (F± the vector fields before and after, J the impact
map's Jacobian, δt* = -δg / ġ⁻ the shift of the impact instant). On a bouncing
ball that is half of the derivative, at every step size.

With :class:`~nsga_jax.ImpactTimeAdjoint` each step where a contact closes
(active in the step's velocity problem and not in the previous step's,
approaching at t_n) gets the derivative of a continuous-time rebuild of that
step, exact to first order in h, while its value stays the scheme's:

1. the impact instant t_n + τ is the first root (in [-h, h]) of a closing
   contact's gap along the smooth motion ``q(s) = q_n + s v_n + s²/2 a_n``
   (a_n: the acceleration at t_n with the bilateral constraints at
   acceleration level); Newton finds it, the implicit function theorem gives
   its derivative;
2. at that instant Newton's impact law acts on the contacts of the step's
   velocity problem and the bilateral constraints hold at velocity level:
   ``M (v⁺ - v⁻) = G_Cᵀ Λ`` with ``G_j v⁺ = -e_j G_j v⁻`` (a Delassus solve);
   where the model has friction (``model.n_friction > 0``, static), Coulomb's
   law also acts on the tangential impulses of the frictional contacts in the
   impact, stick (γ_T⁺ = 0 inside |P_T| <= μ P_N) or slip (P_T = -μ P_N
   γ_T⁺/|γ_T⁺|), solved by semi-smooth Newton and differentiated by the
   implicit function theorem with the stick/slip set frozen
   (:func:`~nsga_jax._impact_time_friction.frictional_impact`);
3. the motion goes on for h - τ with the acceleration a_n, projected so that
   the contacts that stay closed (e = 0, or already closed) and the bilateral
   constraints hold at acceleration level; with friction, convective terms
   included, a closed contact that still slips carries the sliding force
   -μ N γ_T⁺/|γ_T⁺| and one that sticks is held sticking
   (:func:`~nsga_jax._impact_time_friction.continuation`).

Simultaneous contacts share the earliest instant. Steps without a closing
contact keep the scheme's derivative exactly. A frictionless model traces
the frictionless rebuild only.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax

from ._custom_types import Scalar, Vector
from ._impact_time_friction import continuation, frictional_impact
from ._integrators.base import StepState
from ._integrators.contact_rows import has_friction
from ._integrators.linalg import dense_solve, masked_solve
from ._integrators.model_terms import consistent_acceleration, is_unilateral, restitution
from ._integrators.operators import Operators
from ._integrators.records import StepOutput
from ._integrators.residuals import ROUNDOFF_FACTOR
from ._models.base import Model

NEWTON_ITERATIONS = 6
"""Newton iterations on the impact instant (the gap along a quadratic motion)."""


def closing_contacts(model: Model, G: jax.Array, state: StepState, out: StepOutput,
                     was_active: jax.Array) -> jax.Array:
    """Unilateral contacts (nu,) that close during the step: active in the step's
    velocity problem, not active in the previous step's (``was_active``), and
    approaching at t_n. The gap at t_n may be negative (Moreau–Jean penetrates
    before it detects). A contact the step's smooth motion held
    (``DS(persistent_contacts=True)``: closed and not separating at t_n) is
    not closing."""
    nb = model.n_bilateral
    gdot = G[nb:] @ state.v
    closing = out.active_velocity[nb:] & ~was_active & (gdot < 0)
    return closing if state.persistent is None else closing & ~state.persistent[nb:]


def initially_active(model: Model, q0: Vector) -> jax.Array:
    """Contacts (nu,) touching at t0 (gap within round-off of zero): not closing at the first step."""
    gap = model.unilateral(q0)
    return gap <= ROUNDOFF_FACTOR * jnp.finfo(gap.dtype).eps * (1.0 + jnp.linalg.norm(q0))


def impact_instant(model: Model, q: Vector, v: Vector, a: Vector, h: Scalar, closing: jax.Array) -> Scalar:
    """τ: the earliest root of a closing contact's gap along ``q + s v + s²/2 a``,
    searched in [-h, h] (a root before t_n: the contact had penetrated at t_n);
    h if none. Differentiable by the implicit function theorem."""

    def gaps_at(s):  # (nu,) gaps, contact j at its own instant s_j
        return jnp.diagonal(jax.vmap(lambda sj: model.unilateral(q + sj * v + 0.5 * sj**2 * a))(s))

    def gaps_and_rates(s):
        return jax.jvp(gaps_at, (s,), (jnp.ones_like(s),))

    nu = model.n_unilateral
    s = jnp.zeros((nu,), q.dtype)
    s_sg = lax.stop_gradient(s)
    for _ in range(NEWTON_ITERATIONS):
        g, rate = gaps_and_rates(s_sg)
        s_sg = jnp.clip(s_sg - g / jnp.where(rate < 0, rate, -1.0), -h, h)
    s_sg = lax.stop_gradient(s_sg)
    g, rate = gaps_and_rates(s_sg)
    rate = lax.stop_gradient(jnp.where(rate < 0, rate, -1.0))
    s = s_sg - g / rate + lax.stop_gradient(g / rate)  # value s*, derivative -δg/ġ (IFT)
    return jnp.min(jnp.where(closing, s, h))


def _constrained(M: jax.Array, G: jax.Array, rows: jax.Array, y: Vector, target: jax.Array) -> Vector:
    """x closest to y in the M-norm with ``G_j x = target_j`` on ``rows``:
    ``x = y + M⁻¹ G_Rᵀ μ`` with the Delassus system ``(G M⁻¹ Gᵀ)_R μ_R =
    (target - G y)_R`` (redundant rows, a box landing flat, handled by
    :func:`~nsga_jax._integrators.linalg.masked_solve`'s shift)."""
    Minv_Gt = dense_solve(M)(G.T)
    mu = masked_solve(G @ Minv_Gt, target - G @ y, rows)
    return y + Minv_Gt @ mu


def dense_jacobian(model: Model, ops: Operators, q: Vector) -> jax.Array:
    """g_q(q) as a dense (nc, n) array: the rebuild assembles M and g_q, also
    for a model whose run keeps its rows node by node (a matrix-free model:
    impact-time derivatives are then for sizes whose M fits in memory)."""
    G = ops.constraints.jacobian(model, q)
    return G if isinstance(G, jax.Array) else model.constraint_jacobian(q)


def rebuilt_step(model: Model, ops: Operators, state: StepState, out: StepOutput, h: Scalar,
                 closing: jax.Array) -> tuple[Vector, Vector]:
    """(q, v) at t_n + h from the continuous-time rebuild of an impact step (see module)."""
    q, v, t = state.q, state.v, state.t
    a = consistent_acceleration(model, t, q, v)
    tau = impact_instant(model, q, v, a, h, closing)
    q_hit = q + tau * v + 0.5 * tau**2 * a
    v_minus = v + tau * a
    G = dense_jacobian(model, ops, q_hit)
    M = model.mass(q_hit)
    e = restitution(model, q.dtype)
    joints = ~is_unilateral(model)
    rate_minus = G @ v_minus
    in_impact = out.active_velocity | joints
    # contacts that stay closed after the impact (no rebound), and the joints
    stays = in_impact & (e * jnp.abs(rate_minus) <= 1e-12 * (1.0 + jnp.abs(rate_minus)))
    if has_friction(model):  # static: a frictionless model traces the Delassus solves below
        v_plus = frictional_impact(model, M, G, q_hit, v_minus, in_impact, e)
        a_plus = continuation(model, M, G, q_hit, v_minus, v_plus, a, stays | joints)
    else:
        v_plus = _constrained(M, G, in_impact, v_minus, -e * rate_minus)
        a_plus = _constrained(M, G, stays | joints, a, jnp.zeros_like(e))
    rest = h - tau
    return q_hit + rest * v_plus + 0.5 * rest**2 * a_plus, v_plus + rest * a_plus


def with_impact_time_sensitivity(model: Model, ops: Operators, state: StepState, new: StepState,
                                 out: StepOutput, h: Scalar, was_active: jax.Array,
                                 located: jax.Array | bool = False) -> tuple[StepState, StepOutput]:
    """The step's state and record with the same values, and at a step where a
    contact closes, the derivative of :func:`rebuilt_step` in place of the
    scheme's derivative of (q, v). ``was_active``: the previous step's velocity
    active set on the contacts (nu,). ``located``: the step was split at its
    impact instants (``DS(impact_instants=True)``), whose derivative already
    moves the instants with the parameters: kept as the scheme's."""
    G_n = dense_jacobian(model, ops, state.q)
    closing = lax.stop_gradient(closing_contacts(model, G_n, state, out, was_active))
    any_closing = jnp.any(closing) & ~jnp.asarray(located)

    # checkpointed: a cond's residuals are stored for every step (zeros where the
    # branch is not taken), and the rebuild's dense factorisations would make
    # them O(n²) per step; recomputing the branch in the backward pass keeps
    # them O(n).
    @jax.checkpoint
    def carrier(args):  # value 0, derivative that of the rebuilt step
        st, o = args
        q_r, v_r = rebuilt_step(model, ops, st, o, h, closing)
        return q_r - lax.stop_gradient(q_r), v_r - lax.stop_gradient(v_r)

    def nothing(args):
        return jnp.zeros_like(new.q), jnp.zeros_like(new.v)

    dq, dv = lax.cond(any_closing, carrier, nothing, (state, out))
    q = jnp.where(any_closing, lax.stop_gradient(new.q) + dq, new.q)
    v = jnp.where(any_closing, lax.stop_gradient(new.v) + dv, new.v)
    return eqx.tree_at(lambda s: (s.q, s.v), new, (q, v)), eqx.tree_at(lambda r: (r.q, r.v), out, (q, v))
