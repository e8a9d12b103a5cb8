"""The smooth motion with its persistent contacts: ``DS(persistent_contacts=True)``.

The paper's smooth sub-problem (eqs. 33-34) carries the bilateral
constraints only; the force of a unilateral contact is left to the position
correction and the velocity jump, which integrate it at first order (§2: "dw
is integrated using a first-order Euler implicit scheme"). For an impact
that is the right split. For a contact that persists over many steps (a
block resting on a table, a block turning about a sticking corner, a box
sliding on the floor) it is not: the contact force is then a smooth force,
and leaving it to the jumps makes the whole motion first order. On the
rocking block turning about its sticking corner, the energy rises by
2.2e-7 of its start per step at h = 1e-3 s (docs/friction.md).

With this option the smooth sub-problem also carries the *held* contacts:
the unilateral contacts that were closed at the end of the last step
(active in its velocity jump, or carried with a compressive force by its
smooth motion). Each is a candidate row of the smooth motion at velocity
level, with the same augmented law the velocity jump uses, on the smooth
forces instead of the impulses:

    M(q̃) v̇̃ - f(q̃, ṽ, t) - g_qᵀ P̃ = 0,
    σ̃ = ks λ̃ - ps g_q(q̃) ṽ,   P̃_N = σ̃_N where σ̃_N >= 0 (the contact
    pushes: the normal velocity vanishes) and 0 otherwise (it lets go),

and, with Coulomb friction, the tangential force P̃_T = proj_{D(μ P̃_N)}(ks
λ̃_T - p̃_T g_T ṽ) of Alart and Curnier's law (:mod:`~nsga_jax._integrators.friction`)
with penalties p̃_T = m_T / h (the contacts' effective masses per step, so
that they scale like ps = m̄/h). A sticking corner is then a pin of the
smooth motion, a sliding contact a friction force in it, and the smooth
acceleration v̇̃ (and so the generalized-α acceleration) holds the contact
forces: the motion is second order again. The position correction and the
velocity jump are unchanged; on a held contact they have nothing left but
the drift of the velocity-level rows and the round-off. A contact that is
not held (open at the step's start, or closing inside the step) is an
impact, resolved by the jumps as in the paper. The bilateral rows are the
candidates they always were (always active).

Records stay physical: a held contact's impulse over the step is recorded
as the velocity jump's plus h times its smooth force
(:func:`held_impulses`), so that Λ / h is still the mean contact force.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

from .._custom_types import Scalar, ScalarLike, Vector
from .._models.base import Model
from .base import StepState
from .contact_law import NormalLaw
from .contact_rows import has_friction, velocity_rows
from .friction import FrictionLaw, restarted
from .impact_instants import contact_rows, sticking_acceleration
from .linalg import saddle_acceleration
from .model_terms import convective, curvature, is_unilateral
from .newton import NewtonResult, Problem, solve
from .records import VelocityAux
from .residuals import ROUNDOFF_FACTOR, Scaling, constraint_floor, roundoff_floor
from .subproblem_inputs import SmoothInputs


class HeldAux(NamedTuple):
    """What the smooth residual with held contacts hands on, at its iterate:
    the active rows (nc,), the augmented normal multipliers σ̃ (nc,) [N]
    (the physical bilateral reactions on the first nb rows), the tangential
    forces P̃_T (nf · d,) [N] (empty without friction), the rows' Jacobian
    (nc + nf · d, n) and the frictional contacts (nf,) bool that stick:
    their augmented tangential multiplier σ̃_T strictly inside the disk of
    radius μ P̃_N (a sliding contact's lies outside it by p̃_T |γ_T|)."""

    active: jax.Array
    aug: jax.Array
    tangential: jax.Array
    jacobian: jax.Array
    sticking: jax.Array

    def normal_forces(self) -> jax.Array:
        """P̃_N (nc,) [N]: σ̃ on the active rows, zero elsewhere."""
        return jnp.where(self.active, self.aug, 0.0)


def smooth_start(model: Model, v_pred: Vector):
    """Newton's start of the smooth motion with held contacts: the predictor's
    ṽ, every multiplier zero (nc normal and, with friction, nf · d tangential)."""
    return (v_pred, jnp.zeros((model.n_constraints + model.n_friction * model.friction_dim,), v_pred.dtype))


def smooth_problem(inputs: SmoothInputs) -> Problem:
    """Step 1 with the held contacts ``inputs.held`` (nc,) bool as candidate
    rows (module docstring): unknowns x = (ṽ, λ̃) with λ̃ over every
    constraint row and, with friction, the tangential rows; ``aux`` is a
    :class:`HeldAux`."""
    model, ops, (tol_r, tol_f, _), t, h = inputs.model, inputs.ops, inputs.tol, inputs.t, inputs.h
    co, q_pred, v_pred = inputs.co, inputs.q_pred, inputs.v_pred
    assert inputs.held is not None and inputs.offset is None, "DS's smooth motion with its held contacts"
    n, nc = model.n_dof, model.n_constraints
    ks = ps = Scaling.of(model, h).ks
    c_vd, c_q = co.vd_per_v(h), co.q_per_v(h)
    f_pred = ops.force.reference(model, q_pred, v_pred, t)
    unilateral = is_unilateral(model)
    candidates = ~unilateral | inputs.held
    law: NormalLaw | FrictionLaw = NormalLaw(candidates, unilateral, ks, ps)
    if has_friction(model):  # the penalties fixed at the predictor for the whole sub-problem
        GT = model.tangent_jacobian(q_pred)
        law = FrictionLaw.of(model, candidates, unilateral, ks, ps,
                             jnp.diagonal(ops.mass.matrix(model, q_pred)) / h, GT)

    def state(vt):
        return q_pred + c_q * (vt - v_pred), c_vd * (vt - v_pred)

    def rows(q):
        return velocity_rows(model, q, ops.constraints.jacobian(model, q))

    def build(law: NormalLaw | FrictionLaw) -> Problem:
        def residual(x):
            vt, lam = x
            q, vd = state(vt)
            f = ops.force.near(model, f_pred, q, vt, t)
            inertia = ops.mass.product(model, q, vd)
            G = rows(q)
            res = law.residual(inertia, f, G, G @ vt, lam, tol_r, tol_f)
            active, aug, tangential = res.aux
            if not isinstance(law, FrictionLaw):
                empty = jnp.zeros((0,), q.dtype)
                return res._replace(aux=HeldAux(active, aug, empty, G, empty.astype(bool)))
            d, normals = law.d, jnp.asarray(law.normals)
            sigma = law.k * lam[nc:].reshape(-1, d) - law.p_t[:, None] * (G[nc:] @ vt).reshape(-1, d)
            radius = law.mu * jnp.where(active, aug, 0.0)[normals]
            sticking = (radius > 0) & (jnp.sum(sigma**2, axis=1) < radius**2)
            return res._replace(aux=HeldAux(active, aug, tangential, G, sticking))

        def linearise(x, res):
            def matrix():  # eq. 47's top-left block with every active row's curvature
                vt, _ = x
                q, vd = state(vt)
                K, C, K_norm, C_norm = ops.force.tangents(model, q, vt, t)
                Ks = K + model.inertia_stiffness(q, vd) - curvature(model, q, res.aux.normal_forces())
                return c_vd * ops.mass.matrix(model, q) + C + c_q * Ks, K_norm, C_norm

            return ops.smooth.factored(matrix)

        def correct(x, res, matrix):
            vt, lam = x
            q, _ = state(vt)
            G = res.aux.jacobian
            floor = roundoff_floor(1.0, matrix.K_norm, matrix.C_norm, q, vt,
                                   c_vd * ops.mass.norm(model, q) * jnp.linalg.norm(vt))
            floor = floor + constraint_floor(ks, G, vt)
            # d(g_q(q̃(ṽ)) ṽ)/dṽ: the normal rows' convective term; the tangential rows' is left out
            # (Newton's matrix only: the residual is exact)
            conv = convective(model, q, vt)
            G_low = G + c_q * jnp.concatenate([conv, jnp.zeros((G.shape[0] - nc, n), G.dtype)])
            return law.correction(matrix, res.r[:n], res.r[n:], G, G_low, lam, G @ vt, res.bound), floor

        # damped whatever the law, as the paper's smooth motion (subproblems.smooth_problem)
        return Problem(residual, linearise, correct, line_search=True, **restarted(law, build))

    return build(law)


def pinned_and_stuck(model: Model, smooth: HeldAux) -> tuple[jax.Array, jax.Array | None]:
    """The contacts the step's position correction and velocity jump treat
    as joints: the unilateral rows (nc,) bool the smooth motion held with a
    pushing force and, with friction, those of them (nf,) bool that stick in
    it (:attr:`HeldAux.sticking`; the friction force on the disk's edge, by
    round-off, held a sliding block still): their gap and
    rate and, where stuck, their slip go to zero both ways. The smooth
    motion holds them at velocity level only, at q̃; the correction moves q
    and with it the rows, and the drift, which a unilateral row's pushing
    multiplier cannot take back where it lifts the contact, built up (the
    rocking block's pivot rose by 7e-9 m over two seconds, and its rocking
    never ended). In an impact step nothing is held (:func:`smooth_solve`),
    so nothing is pinned: a held contact is free to lift there."""
    pinned = is_unilateral(model) & smooth.active & (smooth.aug > 0)
    if not has_friction(model):
        return pinned, None
    return pinned, pinned[jnp.asarray(model.friction_normals)] & smooth.sticking


def smooth_solve(inputs: SmoothInputs, max_iter: int, factorisation) -> NewtonResult:
    """Step 1 with the held contacts ``inputs.held``, or, where a contact
    that is not held closes by the smooth motion's end (an impact inside the
    step: its gap at q̃ is negative), with none held: the paper's smooth
    motion for that step, from the same predictor (with nothing held, the
    first solve is that motion already). Held, the old contact
    carries the smooth motion through the whole step as if the impact came
    at its end; a block turning about its pivot gains the step's angular
    acceleration there and falls through the floor at the landing corner,
    energy the jumps do not take back: on the rocking block's small, late
    swings the impacts then gained more than they lost, and it never came
    to rest.

    The predictor keeps the held acceleration in a (the pivot's force):
    predicted instead from a state restarted with the acceleration without
    contacts (the paper's step exactly), the rocking block lost its swings
    too early, as the paper's step does (60 s, `bench_settling.py`: landing
    times 0.17 to 0.32 s off at h = 1e-3 to 4e-3 s, against 17 to 48 ms
    with the held predictor)."""
    model = inputs.model
    assert inputs.held is not None
    start = smooth_start(model, inputs.v_pred)
    sol = solve(smooth_problem, inputs, start, max_iter, factorisation, name="smooth_motion")
    q = inputs.q_pred + inputs.co.q_per_v(inputs.h) * (sol.x[0] - inputs.v_pred)
    closing = jnp.any(is_unilateral(model) & ~inputs.held & (model.constraints(q) < 0.0))
    dropped = closing & jnp.any(inputs.held)
    unheld = dataclasses.replace(inputs, held=jnp.zeros_like(inputs.held))
    return lax.cond(dropped, lambda: solve(smooth_problem, unheld, start, max_iter, factorisation,
                                           name="smooth_motion_impact"), lambda: sol)


def held_after(model: Model, smooth: HeldAux, velocity: VelocityAux, rate: jax.Array, q: Vector, h) -> jax.Array:
    """The contacts (nc,) bool the next step's smooth motion holds: the
    unilateral rows active with a pushing impulse in this step's velocity
    jump (a contact that closed in it) or held by this step's smooth motion
    with a pushing force, unless the step ends with them separating: their
    rate ``rate`` = g_q v (nc,) at the step's end above the round-off of a
    gap over one step, 64 eps (|g_q| |q|) / h. A contact that separates (a
    ball bouncing off, e > 0; an impact's other side, the rocking block's
    old pivot once the new corner has landed) is not held: its smooth law
    would let it go, but held, its landing within the next step would not
    count as an impact (:func:`smooth_solve`). The cut stays at round-off:
    the pivots of the rocking block's last, small swings separate slowly.
    Measured without the cut (h = 2e-3 s, 4 s): the block still came to
    rest, at 2.6e-12 rad (with it: 2.5e-14 at the end of the 60 s benchmark)."""
    unilateral = is_unilateral(model)
    G = smooth.jacobian[:model.n_constraints]
    separating = rate > ROUNDOFF_FACTOR * jnp.finfo(q.dtype).eps * (jnp.abs(G) @ jnp.abs(q)) / h
    closed = velocity.active & (velocity.multiplier > 0)
    pushed = smooth.active & (smooth.aug > 0)
    return unilateral & (closed | pushed) & ~separating


def safe_norm(x: jax.Array) -> jax.Array:
    """The norms of the rows of ``x`` (k, d), with a zero derivative at a zero
    row (a contact at rest) instead of NaN."""
    s2 = jnp.sum(x**2, axis=1)
    return jnp.where(s2 > 0, jnp.sqrt(jnp.where(s2 > 0, s2, 1.0)), 0.0)


def held_acceleration(model: Model, q: Vector, v: Vector, t: Scalar, held: jax.Array, tol_r: ScalarLike,
                      h: ScalarLike = 0.0) -> Vector:
    """The acceleration v̇ (n,) [m/s²] at (q, v, t) with the bilateral rows and
    the ``held`` unilateral contacts (nc,) bool at acceleration level: a held
    contact whose normal multiplier pulls is let go, a frictional one that
    does not slip at (q, v) sticks, and one that slips takes Coulomb's force
    -μ N γ_T / |γ_T|, and one at rest whose sticking force would leave its
    cone slides along that force with μ N (N from the solve with every
    contact at rest sticking). The smooth motion's start, v̇̃_0 = a_0
    (Algorithm 1, lines 2-3, with the contacts closed at t0 held), and its
    restart where the pivot moves (:func:`restart_with_held`): from
    the acceleration without them, the rocking block's first step at
    h = 4e-3 s raised its energy by 2.5e-6; from
    :func:`~nsga_jax._integrators.impact_instants.held_acceleration`, which
    holds every frictional contact sticking, the incline's sliding block ran
    5e-4 m behind its exact motion at h = 1e-3 s (1.5e-9 m from this one).

    A contact slips where its slip speed |γ_T| exceeds ``tol_r`` times
    |g_T| (|v| + h |M⁻¹ f|) [m/s] (the velocity, and what the forces change
    it by over a step h [s], resolved to the Newton tolerance) plus
    round-off: after a velocity jump a sticking corner's slip is zero only
    to the jump's tolerance (5e-14 m/s on the rocking block), and read as a
    slip it took Coulomb's force μ m g sideways, which kicked a block at
    rest into a rocking that never ended. ``h = 0`` at a run's start, where
    v0 is exact."""
    normal = is_unilateral(model)
    held = held | ~normal
    if not has_friction(model):
        return sticking_acceleration(model, q, v, t, held)
    nc, d = model.n_constraints, model.friction_dim
    rows, conv = contact_rows(model, q, v)
    M, f = model.mass(q), model.force(q, v, t)
    normals = jnp.asarray(model.friction_normals)
    mu = jnp.asarray(model.friction_coefficients, q.dtype)
    slip = (rows[nc:] @ v).reshape(-1, d)
    speed = safe_norm(slip)
    # a slip is resolved to tol_r of the contact's velocity and of what the forces change it by in a step
    speed_scale = jnp.linalg.norm(v) + h * jnp.linalg.norm(jnp.linalg.solve(M, f))
    scale = safe_norm(rows[nc:].reshape(-1, d * rows.shape[1])) * speed_scale
    slipping = speed > tol_r * scale + ROUNDOFF_FACTOR * jnp.finfo(q.dtype).eps
    direction = slip / jnp.where(slipping, speed, 1.0)[:, None]

    def with_friction(mask, stick, force):
        """The held normal rows ``mask`` (nc,), the sticking contacts ``stick``
        (nf,) and the sliding ones' tangential forces ``force`` (nf, d)."""
        every = jnp.concatenate([mask, jnp.repeat(stick, d)])
        return saddle_acceleration(M, f + rows[nc:].T @ force.ravel(), jnp.where(every[:, None], rows, 0.0),
                                   jnp.where(every, conv, 0.0))

    none = jnp.zeros((mu.shape[0], d), q.dtype)
    _, lam = with_friction(held, held[normals] & ~slipping, none)  # every contact at rest sticks: its forces
    held = held & ~(normal & (lam[:nc] < 0.0))
    N = jnp.where(held, jnp.maximum(lam[:nc], 0.0), 0.0)[normals]
    tangential = lam[nc:].reshape(-1, d)
    size = safe_norm(tangential)
    over = held[normals] & ~slipping & (size > mu * N)  # beyond its cone: it slides along its sticking force
    stick = held[normals] & ~slipping & ~over
    force = mu[:, None] * N[:, None] * jnp.where(
        slipping[:, None], -direction, tangential / jnp.where(over, size, 1.0)[:, None])
    force = jnp.where((held[normals] & (slipping | over))[:, None], force, 0.0)
    return with_friction(held, stick, force)[0]


def restart_with_held(model: Model, state: StepState, tol_r: ScalarLike, h: ScalarLike) -> StepState:
    """The generalized-α variables restarted at the end of a step of size h
    [s] that holds a contact the step before did not while it held another
    (a pivot that moves from corner to corner), as at t0 (Algorithm 1,
    lines 2-3): v̇̃ = a = :func:`held_acceleration` with the held set there.

    The landing's step is the paper's (:func:`smooth_solve`), whose smooth
    motion falls freely; left in a, that free fall carried on into the steps
    about the new pivot, whose position correction lifted the block back,
    and on the rocking block's last, small swings the energy so pumped in
    matched what the landings took out: a cycle that never died (at tilt
    0.1, h = 2e-3 s, swings of 1.2e-5 rad every four steps). Measured and
    dropped: the same restart at a first landing from free flight (the
    flexible appendage's stiff beam took its tip's elastic force, 1.4e4
    m/s², into a, and the tip left its stop with 11 % more energy); a
    restart where the held set only shrinks (the appendage gained 5 % at the
    step that released its tip); and v̇̃, a shifted by the held contacts'
    acceleration only, keeping what a remembers (the rocking block at its
    default tilt, h = 2e-3 s, then cycled)."""
    assert state.persistent is not None, "a state with its held contacts"
    vd = held_acceleration(model, state.q, state.v, state.t, state.persistent, tol_r, h)
    return dataclasses.replace(state, vd=vd, a=vd)


def not_separating(model: Model, q: Vector, v: Vector, closed: jax.Array) -> jax.Array:
    """The ``closed`` contacts (nc,) bool whose rate g_q v at (q, v) is at
    most its round-off, 64 eps (|g_q| |v|): those the smooth motion holds at
    a start (t0, or the instant after an impact located inside a step,
    :func:`~nsga_jax._integrators.impact_instants.restart_after_impact`),
    where the old pivot of a rocking block has a zero gap and lifts."""
    G = jax.jacfwd(model.constraints)(q)
    rate = G @ v
    return closed & ~(rate > ROUNDOFF_FACTOR * jnp.finfo(q.dtype).eps * (jnp.abs(G) @ jnp.abs(v)))


def held_impulses(h, smooth: HeldAux, impulse: jax.Array, friction: jax.Array | None,
                  model: Model) -> tuple[jax.Array, jax.Array | None]:
    """The step's recorded impulses [N s]: the velocity jump's normal (nc,)
    and tangential (nf · d,) ones plus h times the smooth motion's forces on
    the unilateral rows (the bilateral ones are recorded as λ̃)."""
    unilateral = is_unilateral(model)
    normal = impulse + h * jnp.where(unilateral, smooth.normal_forces(), 0.0)
    if friction is None or friction.shape[0] == 0:
        return normal, friction
    return normal, friction + h * smooth.tangential


__all__ = ["HeldAux", "held_acceleration", "held_after", "held_impulses", "not_separating",
           "restart_with_held",
           "pinned_and_stuck",
           "smooth_problem", "smooth_solve", "smooth_start"]
