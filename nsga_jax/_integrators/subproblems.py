"""The three sub-problems of the nonsmooth generalized-α schemes (paper §3.3).

Each builder takes its named inputs
(:mod:`~nsga_jax._integrators.subproblem_inputs`) and returns the
:class:`~nsga_jax._integrators.newton.Problem`
``(residual, linearise, correct)`` that :func:`~nsga_jax._integrators.newton.newton`
iterates. The model's terms and the iteration matrices are the objects of
``ops`` (:class:`~nsga_jax._integrators.operators.Operators`): ``linearise``
is the sub-problem's matrix at the iterate, ``ops.smooth.factored(...)`` and
so on, which is the precomputed matrix itself where the model's structure
makes it constant and a fresh LU factorisation otherwise
(:mod:`~nsga_jax._integrators.iteration_matrix`):

- :func:`smooth_problem` (eqs. 33-34, matrix 47): unknowns x = (ṽ, λ̃), the
  smooth velocity and the scaled bilateral multipliers, with v̇̃ and q̃ affine in
  ṽ by (44b-c); unilateral constraints ignored;
- :func:`position_problem` (eqs. 37-38, matrix 48): x = (U, ν), q = q̃ + U,
  active set A from ξ = kp ν - pp g(q), with or without the h² f^p term (29);
- :func:`velocity_problem` (eqs. 40-43, matrix 49): x = (W, Λ), v = ṽ + W,
  active set B ⊆ A from σ = kv Λ - pv ġ, with or without the h f* term (8);
  with frictional contacts Λ also holds the tangential impulses
  (:mod:`~nsga_jax._integrators.friction`); the position correction then
  carries the same law on the contact points' slip over the step.

DS runs them once each in sequence; DSn drops the f^p and f* terms (eqs.
31a-b); CS evaluates the smooth problem at the total motion (q̃ + U, ṽ + W)
and iterates all three together.
"""

from __future__ import annotations

import jax.numpy as jnp

from .._custom_types import Scalar, Vector
from .coefficients import GenAlphaCoefficients
from .contact_law import NormalLaw
from .contact_rows import dense_rows, has_friction, velocity_rows
from .friction import FrictionLaw, restarted
from .krylov import element_top_left
from .model_terms import convective, curvature, is_unilateral, pad_bilateral, restitution
from .newton import Problem, Residual, convergence_bound
from .records import PositionAux, VelocityAux
from .residuals import Scaling, constraint_floor, roundoff_floor
from .subproblem_inputs import PositionInputs, Smooth, SmoothInputs, VelocityInputs


def smooth_problem(inputs: SmoothInputs) -> Problem:
    """Step 1: residual [M(q) v̇̃ - f(q, v, t) - g_q^T (ks λ̃ - ps g_q ṽ);  -ks g_q ṽ].

    The unknowns are x = (ṽ, λ̃_scaled); v̇̃ and q̃ follow from ṽ and the predictor
    by (44b-c): v̇̃ = c_vd (ṽ - ṽ_pred), q̃ = q̃_pred + c_q (ṽ - ṽ_pred)
    (:func:`smooth_motion`). DS evaluates the residual at the smooth motion,
    q = q̃, v = ṽ; CS (``offset=(U, W)``) at the total motion q = q̃ + U,
    v = ṽ + W, keeping the bilateral velocity constraint on ṽ. The residual's
    ``aux`` is the physical λ̃ = ks λ - ps g_q ṽ.
    """
    model, ops, (tol_r, tol_f, _), t, h = inputs.model, inputs.ops, inputs.tol, inputs.t, inputs.h
    co, q_pred, v_pred, offset = inputs.co, inputs.q_pred, inputs.v_pred, inputs.offset
    n, nb = model.n_dof, model.n_bilateral
    ks = ps = Scaling.of(model, h).ks
    c_vd, c_q = co.vd_per_v(h), co.q_per_v(h)
    f_pred = ops.force.reference(model, q_pred, v_pred, t)

    def state(vt):
        qt = q_pred + c_q * (vt - v_pred)
        vd = c_vd * (vt - v_pred)
        q, v = (qt, vt) if offset is None else (qt + offset[0], vt + offset[1])
        return qt, vd, q, v

    def residual(x):
        vt, lam = x
        _, vd, q, v = state(vt)
        f = ops.force.near(model, f_pred, q, v, t)
        inertia = ops.mass.product(model, q, vd)
        if nb == 0:
            return Residual(inertia - f, convergence_bound([inertia, f], tol_r, tol_f), jnp.zeros((0,), q.dtype))
        GB = ops.constraints.bilateral(model, q)
        mu = ks * lam - ps * (GB @ vt)
        reaction = GB.T @ mu
        r2 = -ks * (GB @ vt)
        r = jnp.concatenate([inertia - f - reaction, r2])
        return Residual(r, convergence_bound([inertia, f, reaction, r2], tol_r, tol_f), mu)

    def linearise(x, res):
        def matrix():  # eq. 47's top-left block, S_t^s
            vt, _ = x
            _, vd, q, v = state(vt)
            K, C, K_norm, C_norm = ops.force.tangents(model, q, v, t)
            Ks = K + model.inertia_stiffness(q, vd) - curvature(model, q, pad_bilateral(model, res.aux))
            return c_vd * ops.mass.matrix(model, q) + C + c_q * Ks, K_norm, C_norm

        def elements():  # the same block, element by element (a matrix-free model)
            return element_top_left(model, ops, state(x[0])[2], c_vd, c_q)

        return ops.smooth.factored(matrix, elements)

    def correct(x, res, matrix):
        vt, lam = x
        _, vd, q, v = state(vt)
        # v̇̃ = c_vd (ṽ - ṽ_pred) cancels: its round-off is eps c_vd ||M|| ||ṽ||
        floor = roundoff_floor(1.0, matrix.K_norm, matrix.C_norm, q, v,
                               c_vd * ops.mass.norm(model, q) * jnp.linalg.norm(vt))
        if nb == 0:
            return (-matrix.solve(res.r, res.bound), jnp.zeros((0,), vt.dtype)), floor
        GB = ops.constraints.bilateral(model, q)
        floor = floor + constraint_floor(ks, GB, vt)
        G_low = GB if model.linear_constraints else GB + c_q * convective(model, q, vt, bilateral_only=True)
        dv, dlam = matrix.bordered(res.r[:n], res.r[n:], GB, G_low, jnp.ones((nb,), bool), ks, ps)
        return (dv, dlam), floor

    return Problem(residual, linearise, correct, line_search=True)


def smooth_start(v_pred: Vector, nb: int):
    """Newton's starting point of step 1: the predictor's ṽ (v̇̃ = 0), λ̃ = 0."""
    return (v_pred, jnp.zeros((nb,), v_pred.dtype))


def smooth_motion(co: GenAlphaCoefficients, h: Scalar, q_pred: Vector, v_pred: Vector, x, lam_physical) -> Smooth:
    """The smooth motion (q̃, ṽ, v̇̃, λ̃) from step 1's unknowns x = (ṽ, λ̃_scaled), by (44b-c)."""
    vt, _ = x
    dv = vt - v_pred
    return Smooth(q=q_pred + co.q_per_v(h) * dv, v=vt, vd=co.vd_per_v(h) * dv, lam=lam_physical)


def position_problem(inputs: PositionInputs) -> Problem:
    """Step 2: residual [M(q̃) U - h² f^p - g_q^{A T} ξ^A;  -kp g^A;  -(kp²/pp) ν^{Ā}]
    with ξ = kp ν - pp g(q), A = bilaterals ∪ {ξ_j >= 0}; ``aux = (A, ξ, g, g_q)``.
    ``inputs.f_smooth``: the force at the smooth motion; ``with_forces=False`` drops h² f^p (eq. 31b).

    With frictional contacts, the correction also carries Coulomb's law at
    position level (:mod:`~nsga_jax._integrators.friction`): the tangential
    multipliers ν_T act along g_T(q_m) on the slip of the contact points over
    the step, Δ_T = g_T(q_m) (q̃ + U - q_n), q_m = (q_n + q̃)/2
    (``inputs.q_prev`` is q_n), within the disk
    of radius μ times the normal correction ξ_N: a sticking point does not
    move over the step, a sliding one is held back by μ ξ_N. Its Newton
    updates are damped (``Problem.line_search``), as the velocity jump's."""
    model, ops, (tol_r, tol_f, _), t, h = inputs.model, inputs.ops, inputs.tol, inputs.t, inputs.h
    smooth, f_smooth, with_forces, q_prev = inputs.smooth, inputs.f_smooth, inputs.with_forces, inputs.q_prev
    n, nb = model.n_dof, model.n_bilateral
    kp = pp = Scaling.of(model, h).kp
    unilateral = is_unilateral(model)
    if inputs.pinned is not None:  # held by the smooth motion: a zero gap, both ways
        unilateral = unilateral & ~inputs.pinned
    candidates = True if inputs.left_open is None else ~inputs.left_open
    law: NormalLaw | FrictionLaw = NormalLaw(candidates, unilateral, kp, pp)
    GT = None
    if has_friction(model):
        assert q_prev is not None, "friction at position level needs the state q_n"
        # the slip over the step by the midpoint rule: exact to O(|q̃ - q_n|³) on a turning body
        GT = model.tangent_jacobian(0.5 * (q_prev + smooth.q))
        law = FrictionLaw.of(model, candidates, unilateral, kp, pp, None, GT)  # tangential penalty pp, as the normal
        law = law._replace(stuck=inputs.stuck)
    curved_joints = bool(with_forces and nb and not ops.constraints.is_constant)  # g_q^B changes with q
    GB_smooth = ops.constraints.bilateral(model, smooth.q) if curved_joints else None

    def f_p(q, G):
        fp = ops.force.change(model, f_smooth, q, smooth.v, t)
        if curved_joints:
            fp = fp + (G[:nb] - GB_smooth).T @ smooth.lam  # (g_q^T - g̃_q^T) λ̃, eq. 29
        return fp

    def law_rows(G, g, q):
        """The rows the law constrains: g_q and the gaps g(q) and, with friction,
        below them g_T and the contact points' slip over the step Δ_T."""
        if GT is None:
            return G, g
        return jnp.concatenate([dense_rows(G), GT]), jnp.concatenate([g, GT @ (q - q_prev)])

    def build(law: NormalLaw | FrictionLaw) -> Problem:
        """The sub-problem with the contact law ``law`` (:func:`~nsga_jax._integrators.friction.restarted`)."""
        def residual(x):
            U, nu = x
            q = smooth.q + U
            g = model.constraints(q)
            G = ops.constraints.jacobian(model, q)
            inertia = ops.mass.product(model, smooth.q, U)
            force = h**2 * f_p(q, G) if with_forces else jnp.zeros_like(U)
            G_all, rows = law_rows(G, g, q)
            res = law.residual(inertia, force, G_all, rows, nu, tol_r, tol_f)
            return res._replace(aux=PositionAux(res.aux[0], res.aux[1], gap=g, jacobian=G))

        def linearise(x, res):
            def matrix():  # eq. 48's top-left block, S_t^p: -d(g_q^{A T} ξ^A)/dq - h² df^p/dq
                U, _ = x
                active, xi, _, _ = res.aux
                q = smooth.q + U
                # the penalty term is left to solve_bordered
                mu = jnp.where(active, xi, 0.0)
                A = ops.mass.matrix(model, smooth.q)
                K_norm = C_norm = jnp.zeros((), q.dtype)
                if with_forces:
                    K, _, K_norm, C_norm = ops.force.tangents(model, q, smooth.v, t)
                    mu = mu + h**2 * pad_bilateral(model, smooth.lam)
                    A = A + h**2 * K
                return A - curvature(model, q, mu), K_norm, C_norm

            def elements():  # M + h² K element by element (a matrix-free model: affine constraints)
                return element_top_left(model, ops, smooth.q + x[0], 1.0, h**2 if with_forces else 0.0)

            return ops.position.factored(matrix, elements)

        def correct(x, res, matrix):
            U, nu = x
            G = res.aux.jacobian
            q = smooth.q + U
            floor = constraint_floor(kp, G, q)
            if with_forces:
                floor = floor + roundoff_floor(h**2, matrix.K_norm, matrix.C_norm, q, smooth.v)
            if GT is not None:
                floor = floor + constraint_floor(kp, GT, q - q_prev)
            G_all, rows = law_rows(G, res.aux.gap, q)
            dU, dnu = law.correction(matrix, res.r[:n], res.r[n:], G_all, G_all, nu, rows, res.bound)
            return (dU, dnu), floor

        return Problem(residual, linearise, correct, line_search=law.damped, **restarted(law, build))

    return build(law)


def velocity_problem(inputs: VelocityInputs) -> Problem:
    """Step 3: residual [M(q) W - h f* - g_q^{B T} σ^B;  -kv ġ^B;  -(kv²/pv) Λ^{B̄}] with
    ġ = g_q v + e g_{q,n} v_n, σ = kv Λ - pv ġ, B = bilaterals ∪ {j ∈ A : σ_j >= 0};
    ``aux = (B, σ, ġ, P_T)``. ``candidates`` is A; ``G_prev_v_prev`` is g_{q,n} v_n.
    ``with_forces=False`` drops h f* (eq. 31a). With frictional contacts the
    multipliers gain the tangential Λ_T and the residual Alart–Curnier's rows
    (:mod:`~nsga_jax._integrators.friction`); q = q̃ + U is fixed here, so the
    tangents g_T(q) are evaluated once."""
    model, ops, (tol_r, tol_f, _), t, h = inputs.model, inputs.ops, inputs.tol, inputs.t, inputs.h
    smooth, U, candidates, f_smooth = inputs.smooth, inputs.U, inputs.candidates, inputs.f_smooth
    G_prev_v_prev, with_forces = inputs.G_prev_v_prev, inputs.with_forces
    n, nb = model.n_dof, model.n_bilateral
    kv = pv = Scaling.of(model, h).kv
    unilateral = is_unilateral(model)
    if inputs.pinned is not None:  # held by the smooth motion: ġ = 0, both ways
        unilateral = unilateral & ~inputs.pinned
    q = smooth.q + U
    G = ops.constraints.jacobian(model, q)
    restituted = restitution(model, q.dtype) * G_prev_v_prev
    law: NormalLaw | FrictionLaw = NormalLaw(candidates, unilateral, kv, pv)
    if has_friction(model):  # the rows whose rates the law constrains: g_q and g_T
        G = velocity_rows(model, q, G)
        restituted = jnp.concatenate([restituted, jnp.zeros((G.shape[0] - restituted.shape[0],), q.dtype)])
        law = FrictionLaw.of(model, candidates, unilateral, kv, pv, ops.mass.diagonal(model, q),
                             G[model.n_constraints:])._replace(stuck=inputs.stuck)
    f_const = None
    if with_forces:
        # terms of f* (eq. 8) that W does not change: (g_q^T - g̃_q^T) λ̃ - (M(q) - M(q̃)) v̇̃
        f_const = jnp.zeros_like(q)
        if nb and not ops.constraints.is_constant:
            f_const = f_const + (G[:nb] - ops.constraints.bilateral(model, smooth.q)).T @ smooth.lam
        if not model.constant_mass:
            f_const = f_const - (model.mass_product(q, smooth.vd) - model.mass_product(smooth.q, smooth.vd))
        if not model.velocity_dependent_force:  # f(q, v) - f(q̃, ṽ) does not change with W
            assert f_smooth is not None  # given whenever with_forces
            f_const = f_const + ops.force.change(model, f_smooth, q, smooth.v, t)

    def build(law: NormalLaw | FrictionLaw) -> Problem:
        """The sub-problem with the contact law ``law`` (:func:`~nsga_jax._integrators.friction.restarted`)."""
        def residual(x):
            W, Lam = x
            v = smooth.v + W
            gdot = G @ v + restituted
            if with_forces:
                f_star = f_const
                if model.velocity_dependent_force:
                    f_star = f_star + ops.force.change(model, f_smooth, q, v, t)
                force = h * f_star
            else:
                force = jnp.zeros_like(W)
            inertia = ops.mass.product(model, q, W)
            res = law.residual(inertia, force, G, gdot, Lam, tol_r, tol_f)
            active, aug, tangential = res.aux
            return res._replace(aux=VelocityAux(active, aug, gdot[:model.n_constraints], tangential))

        def linearise(x, res):
            def matrix():  # eq. 49's top-left block, S_t^v
                W, _ = x
                A = ops.mass.matrix(model, q)
                if not with_forces:
                    zero = jnp.zeros((), q.dtype)
                    return A, zero, zero
                _, C, K_norm, C_norm = ops.force.tangents(model, q, smooth.v + W, t)
                return A + h * C, K_norm, C_norm

            return ops.velocity.factored(matrix)

        def correct(x, res, matrix):
            W, Lam = x
            v = smooth.v + W
            floor = constraint_floor(kv, G, v)
            if with_forces:
                floor = floor + roundoff_floor(h, matrix.K_norm, matrix.C_norm, q, v)
            dW, dLam = law.correction(matrix, res.r[:n], res.r[n:], G, G, Lam, G @ v + restituted, res.bound)
            return (dW, dLam), floor

        return Problem(residual, linearise, correct, line_search=law.damped, **restarted(law, build))

    return build(law)
