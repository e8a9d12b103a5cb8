"""The decoupled nonsmooth generalized-α scheme (DS), paper §3.3 and Algorithm 1,
and its variant DSn without the f^p and f* terms (eqs. 31a-b).

One step n -> n+1 is the strict sequence

0. predictor (Algorithm 1, lines 5-9);
1. smooth motion -- Newton on Δṽ (and Δλ̃), unilateral constraints ignored;
2. position correction -- semi-smooth Newton on (U, ν);
3. velocity jump -- semi-smooth Newton on (W, Λ), with Coulomb friction
   where the model has it (:mod:`~nsga_jax._integrators.friction`);
4. finalise: q = q̃ + U, v = ṽ + W, a += (1-αf)/(1-αm) v̇̃ (line 41).

Sub-problem 1 never sees U or W and sub-problem 2 never sees W: each takes
only what the previous one returned (:mod:`~nsga_jax._integrators.subproblems`).
What a model does not need is left out at trace time: no multiplier block
without bilateral constraints, no position/velocity sub-problem without
constraints, and for a model with a constant mass and a linear force the
iteration matrices are inverted once per step size, outside the time loop.
Larger nonlinear models keep the LU factors of their iteration matrices in
the state (:attr:`StepState.factorisations`) and refactor only when an update
made with them converges too slowly (:func:`~nsga_jax._integrators.newton.newton`).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax

from .._custom_types import Scalar, ScalarLike, Vector
from .._models.base import Model
from .._util import as_float
from . import persistent_contacts
from .base import (
    AbstractScheme,
    StepState,
)
from .coefficients import GenAlphaCoefficients
from .contact_rows import projection_start
from .impact_instants import open_floor, split_step
from .impact_law import velocity_jump
from .krylov import KRYLOV_MIN_DOF, KrylovOperator, kronecker_mass, linear_tolerance, mass_preconditioner
from .model_terms import consistent_acceleration, force_at
from .newton import solve
from .operators import MatrixKinds, Operators, matrix_kinds, prepare_operators, uses_matrix_free
from .records import (
    NewtonRecord,
    PositionAux,
    StepOutput,
    SubproblemRecord,
    VelocityAux,
    first_failure,
    make_output,
    subproblem_result,
)
from .subproblem_inputs import PositionInputs, SmoothInputs, StepInputs, VelocityInputs
from .subproblems import (
    position_problem,
    smooth_motion,
    smooth_problem,
    smooth_start,
)


class AbstractGenAlpha(AbstractScheme):
    """Shared by the nonsmooth generalized-α schemes: ρ∞, predictor, finalisation."""

    rho_inf: ScalarLike = eqx.field(default=0.8, converter=as_float, kw_only=True)
    krylov_min_dof: int | None = eqx.field(static=True, default=KRYLOV_MIN_DOF, kw_only=True)

    @property
    def coefficients(self) -> GenAlphaCoefficients:
        return GenAlphaCoefficients.from_rho_inf(self.rho_inf)

    def bounds(self):
        return {"rho_inf": (self.rho_inf, 0.0, 1.0)}

    def init(self, model: Model, t0: Scalar, q0: Vector, v0: Vector) -> StepState:
        """Initial state with a consistent smooth acceleration (Algorithm 1, lines 2-3)."""
        real = jnp.result_type(q0, float)  # the state's precision: q0's (float32 or float64)
        q0 = jnp.asarray(q0, real)
        v0 = jnp.asarray(v0, real)
        if self.matrix_free(model):  # v̇̃_0 by conjugate gradients on M's element blocks
            vd0 = self._matrix_free_acceleration(model, t0, q0, v0)
        else:
            vd0 = consistent_acceleration(model, t0, q0, v0)
        return StepState(t=jnp.asarray(t0, real), q=q0, v=v0, vd=vd0, a=vd0)

    def matrix_free(self, model: Model) -> bool:
        """Whether a run of ``model`` assembles no matrix (static): fast paths,
        a matrix-free model and at least ``krylov_min_dof`` coordinates
        (:func:`~nsga_jax._integrators.operators.uses_matrix_free`)."""
        return uses_matrix_free(model, self.fast_paths, self.krylov_min_dof)

    def _matrix_free_acceleration(self, model: Model, t0: Scalar, q0: Vector, v0: Vector) -> Vector:
        """v̇̃_0 = M⁻¹ f by conjugate gradients on M's element blocks; with pinned
        nodes, M v̇ = f + G_Bᵀ λ, G_B v̇ = 0 by the projected solve (:mod:`~nsga_jax._integrators.krylov`)."""
        real = q0.dtype
        preconditioner = mass_preconditioner(kronecker_mass(model, real), 1.0)
        M = model.element_mass(q0).node_blocks() if preconditioner is None else preconditioner.mass
        zero = jnp.zeros((), real)
        mass = KrylovOperator.of(M, zero, zero, linear_tolerance(self.tol_r, real), preconditioner)
        nb = model.n_bilateral
        if nb == 0:
            return consistent_acceleration(model, t0, q0, v0, mass.solve)
        GB = model.constraint_rows(q0).rows(0, nb)
        return mass.bordered(-model.force(q0, v0, t0), jnp.zeros((nb,), real), GB, GB, jnp.ones((nb,), bool),
                             jnp.ones((), real), zero)[0]

    def predict(self, state: StepState, h: Scalar) -> tuple[Vector, Vector, Vector]:
        """Algorithm 1, lines 5-9: the pseudo-acceleration a⁺ (v̇̃ = 0), ṽ and q̃."""
        co = self.coefficients
        a_pred = (co.alpha_f * state.vd - co.alpha_m * state.a) / (1.0 - co.alpha_m)
        v_pred = state.v + h * (1.0 - co.gamma) * state.a + h * co.gamma * a_pred
        q_pred = state.q + h * state.v + h**2 * (0.5 - co.beta) * state.a + h**2 * co.beta * a_pred
        return a_pred, v_pred, q_pred

    def finalise(self, t, q, v, vd, a_pred, factorisations=None, multipliers=None) -> StepState:
        """Algorithm 1, line 41: complete the pseudo-acceleration once, (34c) then holds."""
        return StepState(t=t, q=q, v=v, vd=vd, a=a_pred + self.coefficients.a_per_vd() * vd,
                         factorisations=factorisations, multipliers=multipliers)


class DS(AbstractGenAlpha):
    """Decoupled nonsmooth generalized-α (paper §3.3, Algorithm 1).

    Attributes:
        rho_inf: spectral radius at infinity ρ∞ ∈ [0, 1] (eq. 35).
        tol_r, tol_f: relative and reference tolerances of eq. 51.
        max_iter: Newton iteration cap per sub-problem (static).
        nonsmooth_forces: keep the h² f^p and h f* terms of the jump equations
            (eqs. 30); ``False`` is DSn (eqs. 31). Static.
        reuse_min_dof: with fast paths on, a model with at least this many
            coordinates keeps the factorisation of each non-constant iteration
            matrix from iteration to iteration and from step to step, and
            refactors only when an update made with it converges too slowly
            (modified Newton, :func:`~nsga_jax._integrators.newton.newton`);
            smaller models refactor at every iteration, which costs them less
            than the bookkeeping. Static.
        krylov_min_dof: with fast paths on, a matrix-free model
            (:attr:`~nsga_jax._models.Model.matrix_free`) of at least this many
            coordinates assembles no matrix: its iteration matrices are
            element blocks solved by preconditioned conjugate gradients to a
            tenth of eq. 51's tolerance (:mod:`~nsga_jax._integrators.krylov`).
            ``None``: never. Static.
        impact_law: ``"newton"`` (the default: Newton's restitution) or
            ``"energetic"``: with friction and e > 0, Newton's jump capped so
            that an impact cannot create energy (Kane's paradox;
            :mod:`~nsga_jax._integrators.impact_law`). Static.
        warm_start: start each step's position correction and velocity jump
            from the multipliers the step before converged to, instead of zero
            (the paper's start; zero again after a sub-problem that did not
            converge). Contacts whose active set moves from step to step (a
            stack knocked over) then take fewer Newton iterations (ten
            planar boxes: 1.05 position iterations a step against 1.91);
            bodies at rest take one either way (docs/friction.md, *Warm
            start*). The result differs from the paper's within the Newton
            tolerance. Static.
        persistent_contacts: the smooth motion also carries the unilateral
            contacts that were closed at the end of the last step, their
            forces (and, with friction, stick or slip) in the smooth
            acceleration (:mod:`~nsga_jax._integrators.persistent_contacts`):
            a body resting, sliding or turning about a sticking corner then
            moves at second order; the paper (``False``) leaves their forces
            to the position correction and the velocity jump, at first
            order. With the landings at the ends of their steps, a few of
            the rocking block's runs end in a cycle of swings a few steps
            long that never dies out; with ``impact_instants`` too, none
            (docs/friction.md). Static.
        max_impacts, min_fraction, late, short_fraction: with
            ``impact_instants``, the most instants resolved in a step, the
            fraction of h within which an instant at either end of a span is
            left to the paper's step, the fraction of h a sub-step ends past
            its instant, and the fraction of h below which a lead-in to an
            instant keeps the v̇̃ and a of its start
            (:mod:`~nsga_jax._integrators.impact_instants`). Static.
    """

    nonsmooth_forces: bool = eqx.field(static=True, default=True, kw_only=True)
    reuse_min_dof: int = eqx.field(static=True, default=100, kw_only=True)
    impact_law: str = eqx.field(static=True, default="newton", kw_only=True)
    impact_instants: bool = eqx.field(static=True, default=False, kw_only=True)
    warm_start: bool = eqx.field(static=True, default=False, kw_only=True)
    persistent_contacts: bool = eqx.field(static=True, default=False, kw_only=True)
    max_impacts: int = eqx.field(static=True, default=4, kw_only=True)
    min_fraction: float = eqx.field(static=True, default=1e-6, kw_only=True)
    late: float = eqx.field(static=True, default=1e-9, kw_only=True)
    short_fraction: float = eqx.field(static=True, default=0.1, kw_only=True)

    name = "ds"
    subproblems = ("smooth", "position", "velocity")

    def matrix_kinds(self, model: Model) -> MatrixKinds:
        """The kinds of the smooth, position and velocity iteration matrices
        (:func:`~nsga_jax._integrators.operators.matrix_kinds`): constant for a
        constant mass and a linear force (the smooth and position matrices hold
        the constraints' curvature, so only with affine constraints), else held
        between iterations and steps in models of at least ``reuse_min_dof``
        coordinates, refactored at every iteration in smaller ones."""
        return matrix_kinds(model, needs_constant_G=(True, True, False), enabled=self.fast_paths,
                            hold=model.n_dof >= self.reuse_min_dof, krylov=self.matrix_free(model),
                            holds_stiffness=(True, self.nonsmooth_forces, False),
                            smooth_contacts=self.holds_contacts(model))

    def holds_contacts(self, model: Model) -> bool:
        """Whether the smooth motion carries held contacts (static):
        ``persistent_contacts`` and a model with unilateral contacts."""
        return self.persistent_contacts and model.n_unilateral > 0

    def reused(self, model: Model) -> tuple[bool, bool, bool]:
        """Which sub-problems (smooth, position, velocity) keep a factorisation
        between steps: those whose iteration matrix is :class:`~nsga_jax._integrators.iteration_matrix.Held`
        (static: read from :meth:`matrix_kinds`, nothing is evaluated)."""
        kinds = self.matrix_kinds(model)
        return kinds[0].is_held, kinds[1].is_held, kinds[2].is_held

    def init(self, model: Model, t0: Scalar, q0: Vector, v0: Vector, *, h: ScalarLike = 0.0) -> StepState:
        """The state at t0 (Algorithm 1, lines 2-3), or at a restart. ``h`` [s]:
        with persistent contacts, the step against which a held contact's slip
        counts as zero (:func:`~nsga_jax._integrators.persistent_contacts.held_acceleration`):
        0 at a run's start, where v0 is exact; a restart after a jump passes
        its step, since the jump's slips are zero only to its tolerance."""
        state = super().init(model, t0, q0, v0)
        if self.warm_start and model.n_constraints:  # the first step starts at zero, as without the option
            zero = projection_start(model, state.q)[1]
            state = dataclasses.replace(state, multipliers=(zero, zero))
        if self.impact_instants and model.n_unilateral:  # closed at t0: at a round-off gap
            g0 = model.unilateral(state.q)
            state = dataclasses.replace(state, closed=g0 <= open_floor(g0))
        if self.holds_contacts(model):  # held from t0: the contacts closed there (a round-off gap),
            # and an initial acceleration with them held (a frictional one sticking, a pulling one let go)
            g0 = model.unilateral(state.q)
            held = persistent_contacts.not_separating(model, state.q, state.v, jnp.concatenate(
                [jnp.zeros((model.n_bilateral,), bool), g0 <= open_floor(g0)]))
            vd0 = persistent_contacts.held_acceleration(model, state.q, state.v, state.t, held, self.tol_r, h)
            state = dataclasses.replace(state, vd=vd0, a=vd0, persistent=held)
        reused = self.reused(model)
        if not any(reused):
            return state
        kinds = self.matrix_kinds(model)
        return dataclasses.replace(state, factorisations=tuple(
            kind.empty_like(model, state.q.dtype) if kind.is_held else None  # type: ignore[attr-defined]
            for kind in kinds))

    def prepare(self, model: Model, h: Scalar, t0: Scalar) -> Operators:
        co = self.coefficients
        c_vd, c_q = co.vd_per_v(h), co.q_per_v(h)
        with_forces = self.nonsmooth_forces
        return prepare_operators(
            model, t0, self.matrix_kinds(model),
            (lambda M, K, C: c_vd * M + C + c_q * K,  # eq. 50, S_t^{s*}
             (lambda M, K, C: M + h**2 * K) if with_forces else (lambda M, K, C: M),  # S_t^{p*}
             (lambda M, K, C: M + h * C) if with_forces else (lambda M, K, C: M)),  # S_t^{v*}
            enabled=self.fast_paths, tol_r=self.tol_r, smooth_contacts=self.holds_contacts(model),
        )

    def step(self, model: Model, ops: Operators, state: StepState, h: Scalar) -> tuple[StepState, StepOutput]:
        """Advance one step of size h [s]; returns the new state and the step's record.

        With ``impact_instants`` a contact that closes inside the step is
        resolved at its instant (:func:`~nsga_jax._integrators.impact_instants.split_step`);
        otherwise (the default) this is the paper's step, :meth:`paper_step`."""
        if self.impact_instants and model.n_unilateral:
            return split_step(self, model, ops, state, h)
        return self.paper_step(model, ops, state, h)[:2]

    def impact_operators(self, model: Model, t: Scalar) -> Operators:
        """The operators of an impact of zero duration
        (:func:`~nsga_jax._integrators.impact_instants.impact_jump`): the
        velocity jump's iteration matrix is M (h = 0 in S_t^{v*})."""
        mass = lambda M, K, C: M  # noqa: E731
        return prepare_operators(model, t, self.matrix_kinds(model), (mass, mass, mass), enabled=self.fast_paths,
                                 tol_r=self.tol_r, smooth_contacts=self.holds_contacts(model))

    def paper_step(self, model: Model, ops: Operators, state: StepState, h: Scalar,
                   left_open: jax.Array | None = None) -> tuple[StepState, StepOutput, tuple[Vector, Vector]]:
        """The paper's step of size h [s] (Algorithm 1): the new state, the
        step's record and the smooth motion's end (q̃, ṽ) (n,), (n,) before
        any correction (where a contact the look-ahead missed is located,
        :func:`~nsga_jax._integrators.impact_instants.split_step`).

        ``left_open`` (nc,) bool: constraint rows neither sub-problem may
        activate: the contacts a sub-step leaves open up to their located
        impact instant, at its end, where
        :func:`~nsga_jax._integrators.impact_instants.impact_jump` applies the
        impact (:mod:`~nsga_jax._integrators.impact_instants`); ``None``: none,
        as in the paper."""
        tol = self.tolerances
        t = state.t + h
        a_pred, v_pred, q_pred = self.predict(state, h)

        held = state.factorisations or (None, None, None)
        # 1. smooth motion
        co = self.coefficients
        step = StepInputs(model, ops, tol, t, h)  # what every sub-problem is given
        holds = self.holds_contacts(model)
        smooth_inputs = SmoothInputs(**step.shared(), co=co, q_pred=q_pred, v_pred=v_pred,
                                     held=state.persistent if holds else None)
        if holds:
            sol_s = persistent_contacts.smooth_solve(smooth_inputs, self.max_iter, held[0])
            smooth = smooth_motion(co, h, q_pred, v_pred, sol_s.x, sol_s.aux.aug[:model.n_bilateral])
        else:
            sol_s = solve(smooth_problem, smooth_inputs, smooth_start(v_pred, model.n_bilateral), self.max_iter,
                          held[0], name="smooth_motion")
            smooth = smooth_motion(co, h, q_pred, v_pred, sol_s.x, sol_s.aux)
        qt, vt, vd = smooth.q, smooth.v, smooth.vd
        if model.n_constraints == 0:  # nothing to project: U = W = 0 exactly
            newton = NewtonRecord.of(self.subproblems, {"smooth": SubproblemRecord.of(sol_s)}, qt.dtype)
            out = make_output(model, t, qt, vt, smooth.lam, newton, subproblem_result("smooth", sol_s))
            return self.finalise(t, qt, vt, vd, a_pred, kept([sol_s], state)), out, (qt, vt)

        f_smooth = force_at(model, qt, vt, t) if self.nonsmooth_forces else None
        # 2. position correction (never sees W)
        pinned = stuck = None
        if holds:
            assert state.persistent is not None  # init gives a state with held contacts their set
            pinned, stuck = persistent_contacts.pinned_and_stuck(model, sol_s.aux)
        sol_p = solve(position_problem, PositionInputs(**step.shared(), smooth=smooth, f_smooth=f_smooth,
                                                       with_forces=self.nonsmooth_forces, q_prev=state.q,
                                                       left_open=left_open, pinned=pinned, stuck=stuck),
                      newton_start(model, qt, state, 0), self.max_iter, held[1], name="position_correction")
        U, _ = sol_p.x
        position: PositionAux = sol_p.aux
        # 3. velocity jump
        G_prev_v_prev = ops.constraints.jacobian(model, state.q) @ state.v
        velocity: VelocityAux
        jump = VelocityInputs(**step.shared(), smooth=smooth, U=U, candidates=position.active, f_smooth=f_smooth,
                              G_prev_v_prev=G_prev_v_prev, with_forces=self.nonsmooth_forces, pinned=pinned,
                              stuck=stuck)
        sol_v, W, velocity = velocity_jump(self.impact_law, jump, newton_start(model, qt, state, 1), self.max_iter,
                                           held[2], tol.tol_r)

        q, v = qt + U, vt + W
        impulse = jnp.where(velocity.active, velocity.multiplier, 0.0)
        friction = velocity.friction
        if holds:
            impulse, friction = persistent_contacts.held_impulses(h, sol_s.aux, impulse, friction, model)
        results = [sol_s, sol_p, sol_v]
        solved = dict(zip(self.subproblems, results))
        newton = NewtonRecord.of(self.subproblems, {k: SubproblemRecord.of(r) for k, r in solved.items()}, q.dtype)
        out = make_output(
            model, t, q, v, smooth.lam, newton, first_failure([subproblem_result(k, r) for k, r in solved.items()]),
            nu=jnp.where(position.active, position.multiplier, 0.0),
            impulse=impulse, g=position.gap, gdot=velocity.rate,
            active_position=position.active, active_velocity=velocity.active, friction=friction,
        )
        multipliers = None if state.multipliers is None else (carried(sol_p), carried(sol_v))
        new = self.finalise(t, q, v, vd, a_pred, kept(results, state), multipliers)
        if holds:  # a smooth motion that did not converge hands on no held contact
            rate = ops.constraints.jacobian(model, q) @ v
            persistent = persistent_contacts.held_after(model, sol_s.aux, velocity, rate, q, h)
            persistent = persistent & sol_s.converged
            new = dataclasses.replace(new, persistent=persistent)
            # a contact newly held while another was (a pivot that moves): a restarts from those held now
            assert state.persistent is not None
            moved = jnp.any(persistent & ~state.persistent) & jnp.any(state.persistent)
            new = lax.cond(moved, lambda: persistent_contacts.restart_with_held(model, new, tol.tol_r, h),
                           lambda: new)
        return new, out, (qt, vt)


def newton_start(model: Model, q: Vector, state: StepState, which: int) -> tuple[Vector, jax.Array]:
    """Newton's start of the position correction (``which`` 0) or the velocity
    jump (1): zero corrections, and zero multipliers
    (:func:`~nsga_jax._integrators.contact_rows.projection_start`, the paper's) or,
    with ``DS(warm_start=True)``, the multipliers the last step converged to."""
    if state.multipliers is None:
        return projection_start(model, q)
    return jnp.zeros_like(q), state.multipliers[which]


def carried(sol) -> jax.Array:
    """The multipliers a sub-problem hands the next step's start: those it
    converged to, or zero (the paper's start) where it did not, so that a
    failed step's iterate (perhaps not finite) never seeds the next."""
    return jnp.where(sol.converged, sol.x[1], jnp.zeros_like(sol.x[1]))


def kept(results, state: StepState) -> tuple | None:
    """The factorisations the sub-problems ended with, for the next step."""
    if state.factorisations is None:
        return None
    return tuple(r.factorisation for r in results) + (None,) * (3 - len(results))


class DSn(DS):
    """DS without the f^p and f* terms of the jump equations (paper eqs. 31a-b)."""

    nonsmooth_forces: bool = eqx.field(static=True, default=False, kw_only=True)

    name = "dsn"

