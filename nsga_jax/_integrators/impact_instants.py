"""Impacts at their instants: a DS step split where a contact closes inside it.

The paper's DS step (like every time-stepping scheme of the field) applies the
impact law at the end of the step that holds the impact, with the velocity of
the step's start plus a whole step of smooth forces: each impact is O(h)
wrong (an elastic ball loses g h of speed at every bounce). With
``DS(impact_instants=True)`` a step looks ahead before it is taken:

1. **Locate.** Along the smooth motion's Taylor path from the step's start,
   p(s) = q + s v + s²/2 v̇̃ (the smooth acceleration, exact for a constant
   force), each unilateral contact that is open at the start (gap above a
   floor, :func:`open_floor`) and closed at the end of the span left is a
   closing contact; its instant s* solves g(p(s)) = 0 (Newton on s, from
   the secant estimate, clipped to the span). The earliest instant wins.
   Where the path sees no contact close but the paper's step (taken
   anyway) closes one that was open at the start, the instant is located
   in the same way on the smooth motion's own cubic (:func:`hermite_path`):
   a stiff member's discrete motion departs from any short Taylor path.
   Where the Taylor path closes a contact but the paper's step closes none
   that was open, nothing is located (a stiff member's smooth acceleration
   sends the path through a stop the motion does not reach).
2. **Split.** The step is taken as sub-steps of the paper's DS step: up to
   the instant (ended a small time ``late`` after it), where the velocity
   jump takes the closing contacts as candidates (whatever the sign of the
   O(s³) gap the Taylor path's instant leaves: a rotating body's vertex can
   stop 1e-9 m short) and applies the impact law with the velocity at the
   instant; then again from the post-impact
   state over what is left of the step, looking ahead once more. At most ``max_impacts`` instants are
   resolved in a step; what is left after them is one paper step (the
   fall-back: an accumulation, as a ball coming to rest).
3. **Across the split** each sub-step starts from the previous one's
   (q, v, v̇̃, a), with coefficients for its own size; after a sub-step that
   ends at an impact, v̇̃ restarts from the post-impact state as at t0 and
   a keeps its offset from it (:func:`restart_after_impact`). A lead-in to
   an instant shorter than ``short_fraction · h`` keeps the v̇̃ and a of
   its start (:func:`keep_accelerations_if_short`).

Contacts closed at the step's start (at a round-off gap, or closed by the
step before: active in its position correction or given an impulse, as
persistent contact, a body at rest, a corner the rocking block turns
about) are never located: the step is the paper's. Neither is an instant within
``min_fraction · h`` of either end of the span (an impact the paper's step
already resolves to that fraction of a step).

A step's record sums its sub-steps' impulses, multipliers, friction impulses
and Newton iterations, keeps the worst residual of each sub-problem and the
first failure, and reports the state at the step's end, the number of impacts resolved
(``StepOutput.instants``) and whether the step fell back (``fallback``).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax

from .._custom_types import Scalar, Vector
from .._models.base import Model
from .._results import RESULTS, code_of
from .base import StepState
from .contact_rows import projection_start
from .impact_law import velocity_jump
from .linalg import saddle_acceleration
from .operators import Operators
from .records import NewtonRecord, StepOutput, SubproblemRecord, make_output, subproblem_result
from .subproblem_inputs import Smooth, VelocityInputs

if TYPE_CHECKING:
    from .ds import DS

LOCATE_ITERATIONS = 6
"""Newton iterations on s for an instant (a quadratic gap needs one; a
smooth gap converges quadratically from the secant estimate)."""


def open_floor(gaps: jax.Array) -> jax.Array:
    """The gap [m] above which a contact counts as open at a step's start:
    1e3 machine epsilons of the largest gap (a contact the position
    correction closed sits at a round-off gap below it)."""
    eps = jnp.finfo(gaps.dtype).eps
    return 1e3 * eps * jnp.maximum(jnp.max(jnp.abs(gaps), initial=0.0), 1.0)


def contact_rows(model: Model, q: Vector, v: Vector) -> tuple[jax.Array, jax.Array]:
    """The rows a motion may hold at (q, v): g_q (nc, n) and, with friction,
    g_T (nf · d, n) below them; and their convective terms (d(rows v)/dq) v."""
    def rate(x):  # the rows' rates at fixed v
        rows = jax.jacfwd(model.constraints)(x)
        return rows @ v if model.n_friction == 0 else jnp.concatenate([rows, model.tangent_jacobian(x)]) @ v

    rows = jax.jacfwd(model.constraints)(q)
    if model.n_friction:
        rows = jnp.concatenate([rows, model.tangent_jacobian(q)])
    return rows, jax.jvp(rate, (q,), (v,))[1]


def sticking_acceleration(model: Model, q: Vector, v: Vector, t: Scalar, held: jax.Array) -> Vector:
    """The acceleration v̇ (n,) [m/s²] at (q, v, t) with the rows ``held``
    (nc,) bool (the bilateral ones among them) at acceleration level, a
    frictional contact sticking; a held contact whose multiplier pulls
    (λ < 0) is released and the acceleration taken again without it."""
    nc = model.n_constraints
    normal = jnp.arange(nc) >= model.n_bilateral
    rows, conv = contact_rows(model, q, v)
    M, f = model.mass(q), model.force(q, v, t)

    def solve(held):
        mask = held if model.n_friction == 0 else jnp.concatenate(
            [held, jnp.repeat(held[jnp.asarray(model.friction_normals)], model.friction_dim)])
        return saddle_acceleration(M, f, jnp.where(mask[:, None], rows, 0.0), jnp.where(mask, conv, 0.0))

    _, lam = solve(held)
    return solve(held & ~(normal & (lam[:nc] < 0.0)))[0]


def held_acceleration(model: Model, state: StepState) -> Vector:
    """The acceleration v̇ (n,) [m/s²] at the state with the bilateral
    constraints and the contacts closed there (``state.closed``) held at
    acceleration level, a frictional one sticking (:func:`sticking_acceleration`):
    the motion until the next contact closes, as an event-driven integrator
    takes it. The smooth acceleration v̇̃ leaves out the contact forces (they
    lie in the position correction and the velocity jump): along it a block
    turning about a resting corner falls freely, its other corner's instant
    O(s²) off."""
    assert state.closed is not None, "held_acceleration needs the closed contacts"
    held = jnp.concatenate([jnp.ones((model.n_bilateral,), bool), state.closed])
    return sticking_acceleration(model, state.q, state.v, state.t, held)


def taylor_path(state: StepState, s: Scalar, acceleration: Vector | None = None) -> Vector:
    """p(s) = q + s v + s²/2 a: the motion from the state, to O(s³) [m], with
    ``a`` the smooth acceleration v̇̃ (``None``) or :func:`held_acceleration`."""
    return state.q + s * state.v + 0.5 * s**2 * (state.vd if acceleration is None else acceleration)


def hermite_path(state: StepState, end: tuple[Vector, Vector], span: Scalar) -> Callable[[Scalar], Vector]:
    """The cubic Hermite interpolant p(s) [m] through (q, v) at s = 0 and the
    smooth motion's end (q̃, ṽ) = ``end`` at s = ``span`` [s]: the scheme's
    own motion over the step, where it departs from any short Taylor path
    (a stiff member's discrete motion)."""
    q1, v1 = end

    def path(s: Scalar) -> Vector:
        tau = s / span
        h00, h10 = 1.0 - tau**2 * (3.0 - 2.0 * tau), tau * (1.0 - tau) ** 2
        h01, h11 = tau**2 * (3.0 - 2.0 * tau), tau**2 * (tau - 1.0)
        return h00 * state.q + h10 * span * state.v + h01 * q1 + h11 * span * v1

    return path


def open_contacts(gaps: jax.Array, closed: jax.Array | None) -> jax.Array:
    """The unilateral contacts (nu,) bool open at a state with ``gaps`` (nu,)
    [m]: a gap above :func:`open_floor` and not among ``closed``
    (``StepState.closed``: what the last step closed stays closed, a resting
    contact)."""
    is_open = gaps > open_floor(gaps)
    return is_open if closed is None else is_open & ~closed


def first_instant(model: Model, state: StepState, span: Scalar, min_fraction: float, h: Scalar,
                  together: Scalar | float = 0.0, hold: bool = False,
                  path: Callable[[Scalar], Vector] | None = None,
                  g0: Vector | None = None) -> tuple[jax.Array, Scalar, jax.Array]:
    """Whether a contact open at ``state`` (:func:`open_contacts`) closes
    inside (0, span] along ``path`` (by default the Taylor path), the
    earliest such instant s* [s] (relative to the state's time), and the
    unilateral contacts (nu,) bool that close by s* + ``together`` [s].

    Instants within ``min_fraction · h`` of 0 or of ``span`` are not
    reported (the paper's step is kept for them). ``hold`` (static): where
    a contact is closed at the state and another is open, the Taylor path's
    acceleration is :func:`held_acceleration` (dense models), else v̇̃.
    ``g0``: the unilateral gaps (nu,) [m] at ``state`` where the caller has
    them."""
    g0 = model.unilateral(state.q) if g0 is None else g0
    is_open = open_contacts(g0, state.closed)
    if path is None:
        acceleration = None
        if hold and state.closed is not None:  # only where a contact is closed and another may close
            acceleration = lax.cond(jnp.any(state.closed) & jnp.any(is_open),
                                    lambda: held_acceleration(model, state), lambda: state.vd)
        path = functools.partial(taylor_path, state, acceleration=acceleration)
    g1 = model.unilateral(path(span))
    closing = is_open & (g1 < 0.0)
    s = span * g0 / jnp.where(closing, g0 - g1, 1.0)  # the secant estimate

    def gap_and_rate(s):
        return jax.jvp(lambda x: model.unilateral(path(x)), (s,), (jnp.ones_like(s),))

    def newton(_, s):
        g, dg = jax.vmap(lambda j, sj: jax.tree.map(lambda a: a[j], gap_and_rate(sj)))(jnp.arange(g0.shape[0]), s)
        return jnp.clip(s - g / jnp.where(dg < 0.0, dg, -1.0), 0.0, span)

    s = lax.fori_loop(0, LOCATE_ITERATIONS, newton, jnp.where(closing, s, span))
    margin = min_fraction * h
    inside = closing & (s > margin) & (s < span - margin)
    instant = jnp.min(jnp.where(inside, s, span))
    return jnp.any(inside), instant, inside & (s <= instant + together)


def restart_after_impact(scheme: DS, model: Model, state: StepState, impact: jax.Array, h: Scalar) -> StepState:
    """After a sub-step that ends at an impact, v̇̃ restarts from the
    post-impact state as at t0 (Algorithm 1, lines 2-3: consistent with
    (q, v⁺), with persistent contacts those closed and not separating held,
    :meth:`DS.init`) and a moves with it, keeping its offset from v̇̃:
    a⁺ = v̇̃⁺ + (a⁻ - v̇̃⁻). The jump changes v, hence the velocity-dependent
    forces, the bilateral constraints' acceleration terms and the contacts
    held: carried across unchanged, v̇̃ and a put an O(1) error into the
    next steps' velocities, a first-order error in the run (docs/scheme.md,
    *Impacts at their instants*). The offset is O(h) for the resolved
    motion; for the modes the step does not resolve it carries the scheme's
    damping: restarted at a⁺ = v̇̃⁺, each of the flexible appendage's
    chattering impacts reset its beam's nodal accelerations to their
    undamped values until Newton found a spurious root
    (docs/impact-instants.md, *A stiff beam's impacts*). ``h`` [s]: the
    run's step (:meth:`DS.init`)."""
    after = scheme.init(model, state.t, state.q, state.v, h=h)
    state = eqx.tree_at(lambda s: (s.vd, s.a), state, (jnp.where(impact, after.vd, state.vd),
                                                       jnp.where(impact, after.vd + state.a - state.vd, state.a)))
    if state.persistent is None:
        return state
    # ... and the contacts the smooth motion holds from there: those closed and not separating
    # (DS(persistent_contacts=True), :mod:`~nsga_jax._integrators.persistent_contacts`)
    assert after.persistent is not None
    return eqx.tree_at(lambda s: s.persistent, state, jnp.where(impact, after.persistent, state.persistent))


def keep_accelerations_if_short(new: StepState, start: StepState, located: jax.Array, size: Scalar, h: Scalar,
                                short_fraction: float) -> StepState:
    """``new`` with the v̇̃ and a of ``start`` where the sub-step from
    ``start`` to ``new`` ends at a ``located`` instant and is shorter than
    ``short_fraction · h`` [s]: a lead-in to an impact near the span's start
    advances q and v only.

    The generalized-α variables belong to the size of the step that made
    them. In the limit of a mode the step does not resolve (ωh ≫ 1: the
    rotations of a geometrically exact beam's nodes) the scheme propagates
    (v, h a); a sub-step of size h' leaves an a of order 1/h', and the next
    sub-step or step of size h multiplies it by h/h'. A lead-in of 7e-4 h
    took the flexible appendage's beam's v̇̃ from 1e6 to 1.6e8 rad/s² and
    the next sub-step's Newton to a spurious root with 2,000 times the
    energy. Kept from the start, v̇̃ and a are O(short_fraction · h) off for
    the resolved motion, and the restart after the impact
    (:func:`restart_after_impact`) takes v̇̃ to the post-impact state anyway.
    The short remainder after an impact near the span's end keeps its own:
    kept there, the slider-crank's stiff rod gained 3 % of the energy
    through its chattering impacts (docs/impact-instants.md, *A stiff
    beam's impacts*)."""
    short = located & (size < short_fraction * h)
    return eqx.tree_at(lambda s: (s.vd, s.a), new,
                       (jnp.where(short, start.vd, new.vd), jnp.where(short, start.a, new.a)))


def impact_jump(scheme: DS, model: Model, state: StepState, before: StepOutput,
                closing: jax.Array) -> tuple[StepState, StepOutput]:
    """The impact of the ``closing`` contacts (nc,) bool at the state's
    instant, of zero duration: the velocity jump (eqs. 40-43 with h = 0: no
    force acts over it) at q from the velocity v⁻ there, Newton's law on
    the rates v⁻ gives, ġ⁺ = -e g_q v⁻, over the closing contacts and those
    the sub-step up to the instant held (``before.active_position``: a
    resting corner that the impact may lift). The sub-step that ends here
    left the closing contacts open (``paper_step(..., left_open=...)``), so
    the contacts that rested over it kept their impulse: in one jump at
    the sub-step's end, an impact that lifts a resting contact took that
    contact's impulse over the sub-step with it (the rocking block landed
    with ω⁺/ω⁻ = 0.841 for Housner's 0.85)."""
    q, v, t = state.q, state.v, state.t
    ops = scheme.impact_operators(model, t)
    G = ops.constraints.jacobian(model, q)
    smooth = Smooth(q=q, v=v, vd=state.vd, lam=jnp.zeros((model.n_bilateral,), q.dtype))
    inputs = VelocityInputs(model=model, ops=ops, tol=scheme.tolerances, t=t, h=jnp.zeros((), q.dtype),
                            smooth=smooth, U=jnp.zeros_like(q), candidates=closing | before.active_position,
                            f_smooth=None, G_prev_v_prev=G @ v, with_forces=False)
    held = state.factorisations[2] if state.factorisations else None  # a model that keeps them: a start
    sol, W, aux = velocity_jump(scheme.impact_law, inputs, projection_start(model, q), scheme.max_iter, held,
                                scheme.tolerances.tol_r)
    v = v + W
    newton = NewtonRecord.of(scheme.subproblems, {"velocity": SubproblemRecord.of(sol)}, q.dtype)
    out = make_output(model, t, q, v, before.lam, newton, subproblem_result("velocity", sol),
                      impulse=jnp.where(aux.active, aux.multiplier, 0.0), gdot=aux.rate,
                      active_velocity=aux.active, friction=aux.friction)
    return dataclasses.replace(state, v=v), out


def with_closed(model: Model, state: StepState, out: StepOutput) -> StepState:
    """``state`` with the unilateral contacts its step closed: active in the
    position correction or given an impulse by the velocity jump (a contact
    just restituted is separating, one resting stays closed); the next step
    does not locate them."""
    nb = model.n_bilateral
    return dataclasses.replace(state, closed=out.active_position[nb:] | out.active_velocity[nb:])


def _merge(acc: StepOutput, out: StepOutput) -> StepOutput:
    """The record of a step made of sub-steps: the last sub-step's state,
    sums of impulses and iterations, the worst residual, the first failure."""
    worse = out.newton.residual * acc.newton.tolerance > acc.newton.residual * out.newton.tolerance
    newton = NewtonRecord(names=out.newton.names, iterations=acc.newton.iterations + out.newton.iterations,
                          residual=jnp.where(worse, out.newton.residual, acc.newton.residual),
                          tolerance=jnp.where(worse, out.newton.tolerance, acc.newton.tolerance))
    ok = code_of(RESULTS.successful)
    return eqx.tree_at(
        lambda o: (o.nu, o.impulse, o.friction, o.active_position, o.active_velocity, o.newton, o.result),
        out, (acc.nu + out.nu, acc.impulse + out.impulse, acc.friction + out.friction,
              acc.active_position | out.active_position, acc.active_velocity | out.active_velocity, newton,
              jnp.where(acc.result != ok, acc.result, out.result)))


def _and_impact(scheme: DS, model: Model, state: StepState, out: StepOutput,
                closing: jax.Array) -> tuple[StepState, StepOutput]:
    """A sub-step that ends at an instant, with the impact applied there:
    its record and the impact's merged."""
    new, jump = impact_jump(scheme, model, state, out, closing)
    return new, _merge(out, jump)


def split_step(scheme: DS, model: Model, ops: Operators, state: StepState,
               h: Scalar) -> tuple[StepState, StepOutput]:
    """One step of size h [s] with its impacts at their instants (module docstring).

    A step where no open contact closes is the paper's step with the run's
    operators ``ops``; a split step prepares the operators of each sub-step's size.
    A contact open at the start that the paper's step closes where the
    Taylor path misses it is located on the smooth motion's own cubic
    (:func:`hermite_path`).

    The sub-steps of a split step are the passes of one loop, whose body
    holds the paper's step once (its first pass ends at the instant located
    above, the next ones locate their own): the rocking block's chunk
    program holds 15,106 equations and compiles in 11 s, against 22,466 and
    15 s with the first sub-step written apart from the loop. The paper's
    step over h stays outside the loop: as the loop's first pass, the steps
    that are not split (nearly all) ran 1.15x (the rocking block) to 2.2x
    (the impacting bar) slower (docs/impact-instants.md, *Compile time*)."""
    hold = not scheme.matrix_free(model)
    nb = model.n_bilateral
    # The paper's step is taken outside the cond (and wasted in the rare split
    # step): measured, the worst case over four scenes is then 1.2x the option
    # off, against 2.2x with it inside (docs/impact-instants.md, *Run time*).
    new, taken, smooth_end = scheme.paper_step(model, ops, state, h)
    g0 = model.unilateral(state.q)  # the start's gaps, evaluated once for the three uses below
    located = first_instant(model, state, h, scheme.min_fraction, h, scheme.late * h, hold, g0=g0)
    closed_by_step = jnp.any((taken.active_position | taken.active_velocity)[nb:] & open_contacts(g0, state.closed))
    located = (located[0] & closed_by_step, *located[1:])  # the Taylor path closes what the step does not: spurious
    missed = ~located[0] & closed_by_step
    located = lax.cond(missed, lambda: first_instant(model, state, h, scheme.min_fraction, h, scheme.late * h,
                                                     path=hermite_path(state, smooth_end, h), g0=g0),
                       lambda: located)

    def split(state):
        t_end = state.t + h

        def take(k, st, left, acc, impacts):
            # pass 0 ends at the instant located over h above; the next passes locate their own (k, the loop's
            # index, is never batched: the conds on it stay branches under vmap)
            found, s, rows = lax.cond(k == 0, lambda: located, lambda: first_instant(
                model, st, left, scheme.min_fraction, h, scheme.late * h, hold))
            located_here = found & (k < scheme.max_impacts)
            size = jnp.where(located_here, s + scheme.late * h, left)  # s < left - min_fraction h < left - late h
            closing = jnp.concatenate([jnp.zeros((nb,), bool), located_here & rows])
            new, out, _ = scheme.paper_step(model, scheme.prepare(model, size, st.t), st, size, closing)
            new = keep_accelerations_if_short(new, st, located_here, size, h, scheme.short_fraction)
            new, out = lax.cond(located_here, lambda: _and_impact(scheme, model, new, out, closing),
                                lambda: (new, out))
            new = restart_after_impact(scheme, model, with_closed(model, new, out), located_here, h)
            merged = lax.cond(k == 0, lambda: out, lambda: _merge(acc, out))
            return new, left - size, ~located_here, merged, impacts + located_here.astype(jnp.int32)

        def next_pass(k, carry):  # a fori_loop of static length (a scan): reverse mode goes through it
            st, left, done, acc, impacts = carry
            return lax.cond(done, lambda: carry, lambda: take(k, st, left, acc, impacts))

        carry = (state, jnp.asarray(h, state.q.dtype), jnp.zeros((), bool), taken, jnp.zeros((), jnp.int32))
        new, _, _, out, impacts = lax.fori_loop(0, scheme.max_impacts + 1, next_pass, carry)
        new = eqx.tree_at(lambda s: s.t, new, t_end)
        out = eqx.tree_at(lambda o: (o.t, o.instants, o.fallback), out,
                          (t_end, impacts, impacts >= scheme.max_impacts))
        return new, out

    return lax.cond(located[0], split, lambda _: (with_closed(model, new, taken), taken), state)


__all__ = ["contact_rows", "first_instant", "held_acceleration", "hermite_path", "keep_accelerations_if_short",
           "open_contacts", "open_floor", "restart_after_impact", "split_step", "sticking_acceleration", "taylor_path",
           "with_closed"]
