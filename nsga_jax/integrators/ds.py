"""The decoupled nonsmooth generalized-α scheme (DS), paper §3.3 and Algorithm 1.

One step n -> n+1 is the strict sequence

0. predictor (Algorithm 1, lines 5-9);
1. :func:`smooth_motion` -- Newton on (ṽ, λ̃) with q̃ and v̇̃ slaved to ṽ by
   (44b-c); unilateral constraints ignored (eqs. 33-34, matrix 47);
2. :func:`position_correction` -- semi-smooth Newton on (U, ν), active set A
   from ξ = kp ν - pp g(q) (eqs. 37-38, matrix 48), with the h² f^p term (29);
3. :func:`velocity_jump` -- semi-smooth Newton on (W, Λ), active set
   B ⊆ A from σ = kv Λ - pv ġ (eqs. 40-43, matrix 49), with the h f* term (8);
4. finalise: q = q̃ + U, v = ṽ + W, a += (1-αf)/(1-αm) v̇̃ (line 41).

Sub-problem 1 never sees U or W and sub-problem 2 never sees W: each takes
only what the previous one returned. What a model does not need is left out
at trace time: no multiplier block without bilateral constraints, no
position/velocity sub-problem without constraints, and for a model with a
constant mass and a linear force the three iteration matrices are inverted
once per step size (:func:`prepare`), outside the time loop.

Multipliers are stored scaled as in the paper (ks λ̃, kp ν, kv Λ are the
physical values); outputs are physical: λ̃ [N], ν [N s²] and the impulse
Λ [N s] (Λ/h is the mean contact force over the step).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Matrix, Scalar, ScalarLike, Vector
from .._util import as_float
from ..models.base import Model
from ..results import Result
from .coefficients import GenAlphaCoefficients
from .linalg import dense_solve, inverse_solve, solve_bordered
from .newton import NewtonResult, Residual, convergence_bound, newton

ROUNDOFF_FACTOR = 64.0
"""The residual floor is ``ROUNDOFF_FACTOR * eps * (||K|| ||q|| + ||C|| ||v||)``
(scaled like the residual), see :mod:`nsga_jax.integrators.newton`."""


# --------------------------------------------------------------------------- data


class StepState(eqx.Module):
    """What the scheme carries from step to step (all float arrays).

    t [s]; q, v (n,): coordinates and velocities; vd (n,): smooth acceleration
    v̇̃; a (n,): generalized-α pseudo-acceleration.
    """

    t: Scalar
    q: Vector
    v: Vector
    vd: Vector
    a: Vector


class StepOutput(eqx.Module):
    """Per-step record (stacked over steps by the time loop).

    Shapes: q, v (n,); lam (nb,): smooth bilateral multipliers [N];
    nu (nc,): position multipliers; impulse (nc,): Λ [N s] on the velocity
    active set; gap (nu,): g^U(q_{n+1}); bilateral (nb,): g^B(q_{n+1});
    bilateral_rate (nb,): g_q^B v_{n+1}; active_position, active_velocity (nc,);
    iterations (3,): Newton iterations of the smooth, position and velocity
    sub-problems; residual, tolerance (3,): final residual norms and their
    bound; result: :class:`~nsga_jax.results.Result` code.
    """

    t: Scalar
    q: Vector
    v: Vector
    lam: jax.Array
    nu: jax.Array
    impulse: jax.Array
    gap: jax.Array
    bilateral: jax.Array
    bilateral_rate: jax.Array
    active_position: jax.Array
    active_velocity: jax.Array
    iterations: jax.Array
    residual: jax.Array
    tolerance: jax.Array
    result: jax.Array


class Operators(eqx.Module):
    """Constant pieces of a model for one step size, computed once (:func:`prepare`).

    Each field is ``None`` when the model's structure does not make it
    constant: M (constant mass), K and C (linear force), G (affine
    constraints), and the inverses of the three iteration matrices with the
    products A^{-1} G^T they need (constant mass, linear force and, for the
    sub-problems that have constraints, affine constraints).
    """

    M: Matrix | None
    K: Matrix | None
    C: Matrix | None
    K_norm: Scalar | None
    C_norm: Scalar | None
    G: jax.Array | None
    smooth_inv: Matrix | None
    smooth_inv_Gt: jax.Array | None
    position_inv: Matrix | None
    position_inv_Gt: jax.Array | None
    velocity_inv: Matrix | None
    velocity_inv_Gt: jax.Array | None


class _Scaling(eqx.Module):
    """Multiplier scalings and penalties (after eq. 50): ks = ps = m̄/h, kp = pp = kv = pv = m̄."""

    ks: Scalar
    kp: Scalar
    kv: Scalar

    @classmethod
    def of(cls, model: Model, h: Scalar) -> "_Scaling":
        mbar = jnp.asarray(model.mbar, dtype=float)
        return cls(ks=mbar / h, kp=mbar, kv=mbar)


# ----------------------------------------------------------------- model helpers


def _mass(model: Model, ops: Operators, q: Vector) -> Matrix:
    return ops.M if ops.M is not None else model.mass(q)


def _tangents(model: Model, ops: Operators, q: Vector, v: Vector, t: Scalar):
    """K, C and their Frobenius norms (for the round-off floor)."""
    if ops.K is not None:
        return ops.K, ops.C, ops.K_norm, ops.C_norm
    K, C = model.tangents(q, v, t)
    if not model.velocity_dependent_force:
        C = jnp.zeros_like(K)
    return K, C, jnp.linalg.norm(K), jnp.linalg.norm(C)


def _force_change(model: Model, q, v, f_ref, t) -> Vector:
    """f(q, v, t) - f_ref. Evaluating f (element assembly, O(n)) is cheaper than a
    dense tangent product; the round-off it leaves is what the Newton floor covers."""
    return model.force(q, v, t) - f_ref


def _jacobian(model: Model, ops: Operators, q: Vector) -> jax.Array:
    """g_q(q) for all constraints, shape (nc, n)."""
    return ops.G if ops.G is not None else model.constraint_jacobian(q)


def _bilateral_jacobian(model: Model, q: Vector) -> jax.Array:
    return jax.jacfwd(model.bilateral)(q)


def _curvature(model: Model, q: Vector, mu: jax.Array) -> Matrix:
    """d(g_q(q)^T mu)/dq at fixed mu (mu over all nc constraints); zero if affine."""
    if model.linear_constraints or model.n_constraints == 0:
        return jnp.zeros((model.n_dof, model.n_dof), q.dtype)
    return jax.jacfwd(lambda x: model.constraint_jacobian(x).T @ mu)(q)


def _bilateral_convective(model: Model, q: Vector, v: Vector) -> jax.Array:
    """G^s = d(g_q^B(q) v)/dq at fixed v, shape (nb, n); zero if affine."""
    if model.linear_constraints:
        return jnp.zeros((model.n_bilateral, model.n_dof), q.dtype)
    return jax.jacfwd(lambda x: _bilateral_jacobian(model, x) @ v)(q)


def _floor(scale: Scalar, K_norm, C_norm, q, v) -> Scalar:
    eps = jnp.finfo(q.dtype).eps
    return ROUNDOFF_FACTOR * eps * scale * (K_norm * jnp.linalg.norm(q) + C_norm * jnp.linalg.norm(v))


def _pad_bilateral(model: Model, lam: jax.Array) -> jax.Array:
    """Embed a bilateral multiplier (nb,) in the full constraint space (nc,)."""
    return jnp.concatenate([lam, jnp.zeros((model.n_unilateral,), lam.dtype)])


def _is_unilateral(model: Model) -> jax.Array:
    return jnp.arange(model.n_constraints) >= model.n_bilateral


# ------------------------------------------------------------------- preparation


def prepare(model: Model, coeffs: GenAlphaCoefficients, h: Scalar, t0: Scalar) -> Operators:
    """Evaluate (and invert) what is constant for this model and step size."""
    n, nb, nc = model.n_dof, model.n_bilateral, model.n_constraints
    zeros = jnp.zeros((n,))
    M = model.mass(zeros) if model.constant_mass else None
    K = C = K_norm = C_norm = None
    if model.linear_force:
        K, C = model.tangents(zeros, zeros, t0)
        K_norm, C_norm = jnp.linalg.norm(K), jnp.linalg.norm(C)
    G = model.constraint_jacobian(zeros) if (model.linear_constraints and nc > 0) else None

    inv = {k: None for k in ("smooth", "position", "velocity")}
    inv_Gt = dict(inv)
    if M is not None and K is not None:
        qv = coeffs.q_per_v(h)
        # The three iteration matrices of eq. 50 without constraint terms. They
        # are constant when the constraint curvature does not enter them:
        # always for the velocity jump, with affine constraints for the others.
        if nb == 0 or G is not None:
            inv["smooth"] = jnp.linalg.inv(coeffs.vd_per_v(h) * M + C + qv * K)
            if nb > 0:
                inv_Gt["smooth"] = inv["smooth"] @ G[:nb].T
        if nc > 0 and G is not None:
            inv["position"] = jnp.linalg.inv(M + h**2 * K)
            inv_Gt["position"] = inv["position"] @ G.T
        if nc > 0:
            inv["velocity"] = jnp.linalg.inv(M + h * C)
            if G is not None:
                inv_Gt["velocity"] = inv["velocity"] @ G.T
    return Operators(
        M=M,
        K=K,
        C=C,
        K_norm=K_norm,
        C_norm=C_norm,
        G=G,
        smooth_inv=inv["smooth"],
        smooth_inv_Gt=inv_Gt["smooth"],
        position_inv=inv["position"],
        position_inv_Gt=inv_Gt["position"],
        velocity_inv=inv["velocity"],
        velocity_inv_Gt=inv_Gt["velocity"],
    )


def consistent_acceleration(model: Model, t0: Scalar, q0: Vector, v0: Vector) -> Vector:
    """v̇̃_0 from the equations of motion with the bilateral constraints at
    acceleration level, unilateral constraints ignored (Algorithm 1, line 2)."""
    M = model.mass(q0)
    f = model.force(q0, v0, t0)
    nb = model.n_bilateral
    if nb == 0:
        return jnp.linalg.solve(M, f)
    GB = _bilateral_jacobian(model, q0)
    convective = jax.jvp(lambda x: _bilateral_jacobian(model, x) @ v0, (q0,), (v0,))[1]
    n = model.n_dof
    S = jnp.block([[M, -GB.T], [GB, jnp.zeros((nb, nb))]])
    sol = jnp.linalg.solve(S, jnp.concatenate([f, -convective]))
    return sol[:n]


# ------------------------------------------------------------------ sub-problems


class SmoothMotion(eqx.Module):
    q: Vector  # q̃_{n+1}
    v: Vector  # ṽ_{n+1}
    vd: Vector  # v̇̃_{n+1}
    lam: jax.Array  # physical λ̃ (nb,)
    newton: NewtonResult


def smooth_motion(
    model: Model,
    ops: Operators,
    coeffs: GenAlphaCoefficients,
    tol: tuple[Scalar, Scalar, int],
    t: Scalar,
    h: Scalar,
    q_pred: Vector,
    v_pred: Vector,
) -> SmoothMotion:
    """Step 1 (eqs. 33-34): Newton on Δṽ (and Δλ̃), unilateral constraints ignored.

    Residual: [M(q̃) v̇̃ - f(q̃, ṽ, t) - g̃_q^T (ks λ̃ - ps g̃_q ṽ);  -ks g̃_q ṽ].
    """
    tol_r, tol_f, max_iter = tol
    nb = model.n_bilateral
    sc = _Scaling.of(model, h)
    ks = ps = sc.ks
    c_vd, c_q = coeffs.vd_per_v(h), coeffs.q_per_v(h)

    def residual(x):
        v, vd, q, lam = x
        f = model.force(q, v, t)
        inertia = model.mass_product(q, vd)
        if nb == 0:
            r = inertia - f
            return Residual(r, convergence_bound([inertia, f], tol_r, tol_f), jnp.zeros((0,)))
        GB = ops.G[:nb] if ops.G is not None else _bilateral_jacobian(model, q)
        mu = ks * lam - ps * (GB @ v)
        reaction = GB.T @ mu
        r2 = -ks * (GB @ v)
        r = jnp.concatenate([inertia - f - reaction, r2])
        return Residual(r, convergence_bound([inertia, f, reaction, r2], tol_r, tol_f), mu)

    def update(x, res):
        v, vd, q, lam = x
        K, C, K_norm, C_norm = _tangents(model, ops, q, v, t)
        floor = _floor(1.0, K_norm, C_norm, q, v)
        if ops.smooth_inv is not None:
            solve = inverse_solve(ops.smooth_inv)
        else:
            M = _mass(model, ops, q)
            Ks = K + model.inertia_stiffness(q, vd) - _curvature(model, q, _pad_bilateral(model, res.aux))
            solve = dense_solve(c_vd * M + C + c_q * Ks)
        if nb == 0:
            dv = -solve(res.r)
            dlam = jnp.zeros((0,), lam.dtype)
        else:
            GB = ops.G[:nb] if ops.G is not None else _bilateral_jacobian(model, q)
            G_low = GB + c_q * _bilateral_convective(model, q, v)
            dv, dlam = solve_bordered(
                solve, res.r[: model.n_dof], res.r[model.n_dof :], GB, G_low,
                jnp.ones((nb,), bool), ks, ps, ops.smooth_inv_Gt,
            )
        return (dv, c_vd * dv, c_q * dv, dlam), floor

    x0 = (v_pred, jnp.zeros_like(v_pred), q_pred, jnp.zeros((nb,), q_pred.dtype))
    sol = newton(residual, update, x0, max_iter)
    v, vd, q, _ = sol.x
    return SmoothMotion(q=q, v=v, vd=vd, lam=sol.aux, newton=sol)


def _augmented_residual(inertia, force, G, c, mu, k, p, candidates, unilateral, tol_r, tol_f):
    """Residual of a projection sub-problem (eqs. 37 and 42), shared by steps 2 and 3.

    With the augmented multiplier ``aug = k mu - p c`` and the active set
    ``candidates ∩ (bilateral ∪ {aug >= 0})``:
    ``[inertia - force - G^T aug_active;  -k c (active);  -(k²/p) mu (inactive)]``.
    Returns the :class:`Residual` with ``aux = (active, aug)``.
    """
    aug = k * mu - p * c
    active = candidates & (~unilateral | (aug >= 0))
    reaction = G.T @ jnp.where(active, aug, 0.0)
    r2 = jnp.where(active, -k * c, -(k**2 / p) * mu)
    r = jnp.concatenate([inertia - force - reaction, r2])
    return Residual(r, convergence_bound([inertia, force, reaction, r2], tol_r, tol_f), (active, aug))


class PositionCorrection(eqx.Module):
    U: Vector
    nu: jax.Array  # physical ν on A (nc,)
    active: jax.Array  # A (nc,)
    g: jax.Array  # constraints at q_{n+1} (nc,)
    newton: NewtonResult


def position_correction(
    model: Model,
    ops: Operators,
    tol: tuple[Scalar, Scalar, int],
    t: Scalar,
    h: Scalar,
    smooth: SmoothMotion,
    f_smooth: Vector,
) -> PositionCorrection:
    """Step 2 (eqs. 37-38): semi-smooth Newton on (U, ν), q = q̃ + U.

    Residual: [M(q̃) U - h² f^p - g_q^{A T} ξ^A;  -kp g^A;  -(kp²/pp) ν^{Ā}],
    ξ = kp ν - pp g(q), A = bilaterals ∪ {j : ξ_j >= 0}.
    """
    tol_r, tol_f, max_iter = tol
    nb, nc = model.n_bilateral, model.n_constraints
    kp = pp = _Scaling.of(model, h).kp
    unilateral = _is_unilateral(model)
    GB_smooth = _bilateral_jacobian(model, smooth.q) if (nb and ops.G is None) else None

    def f_p(q, G):
        fp = _force_change(model, q, smooth.v, f_smooth, t)
        if GB_smooth is not None:
            fp = fp + (G[:nb] - GB_smooth).T @ smooth.lam  # (g_q^T - g̃_q^T) λ̃, eq. 29
        return fp

    def residual(x):
        U, nu = x
        q = smooth.q + U
        g = model.constraints(q)
        G = _jacobian(model, ops, q)
        res = _augmented_residual(
            model.mass_product(smooth.q, U), h**2 * f_p(q, G), G, g, nu, kp, pp,
            True, unilateral, tol_r, tol_f,
        )
        return res._replace(aux=res.aux + (g, G))

    def update(x, res):
        U, nu = x
        active, xi, _, G = res.aux
        q = smooth.q + U
        K, _, K_norm, C_norm = _tangents(model, ops, q, smooth.v, t)
        floor = _floor(h**2, K_norm, C_norm, q, smooth.v)
        if ops.position_inv is not None:
            solve = inverse_solve(ops.position_inv)
        else:
            # -d(g_q^{A T} ξ^A)/dq - h² df^p/dq, penalty term left to solve_bordered
            mu = jnp.where(active, xi, 0.0) + h**2 * _pad_bilateral(model, smooth.lam)
            Mt = _mass(model, ops, smooth.q)
            solve = dense_solve(Mt + h**2 * K - _curvature(model, q, mu))
        n = model.n_dof
        dU, dnu = solve_bordered(
            solve, res.r[:n], res.r[n:], G, G, active, kp, pp, ops.position_inv_Gt
        )
        return (dU, dnu), floor

    x0 = (jnp.zeros_like(smooth.q), jnp.zeros((nc,), smooth.q.dtype))
    sol = newton(residual, update, x0, max_iter)
    active, xi, g, _ = sol.aux
    U, _ = sol.x
    return PositionCorrection(U=U, nu=jnp.where(active, xi, 0.0), active=active, g=g, newton=sol)


class VelocityJump(eqx.Module):
    W: Vector
    impulse: jax.Array  # physical Λ on B (nc,)
    active: jax.Array  # B (nc,)
    gdot: jax.Array  # ġ (nc,)
    newton: NewtonResult


def velocity_jump(
    model: Model,
    ops: Operators,
    tol: tuple[Scalar, Scalar, int],
    t: Scalar,
    h: Scalar,
    smooth: SmoothMotion,
    f_smooth: Vector,
    position: PositionCorrection,
    G_prev_v_prev: jax.Array,
) -> VelocityJump:
    """Step 3 (eqs. 40-43): semi-smooth Newton on (W, Λ), v = ṽ + W.

    Residual: [M(q) W - h f* - g_q^{B T} σ^B;  -kv ġ^B;  -(kv²/pv) Λ^{B̄}],
    ġ = g_q v + e g_{q,n} v_n, σ = kv Λ - pv ġ, B = bilaterals ∪ {j ∈ A : σ_j >= 0}.
    ``G_prev_v_prev`` is g_{q,n} v_n (nc,).
    """
    tol_r, tol_f, max_iter = tol
    nb, nc = model.n_bilateral, model.n_constraints
    kv = pv = _Scaling.of(model, h).kv
    unilateral = _is_unilateral(model)
    q = smooth.q + position.U
    G = _jacobian(model, ops, q)
    e = jnp.concatenate([jnp.zeros((nb,)), jnp.asarray(model.restitution, dtype=q.dtype)])
    restituted = e * G_prev_v_prev
    # Terms of f* that W does not change (eq. 8): (g_q^T - g̃_q^T) λ̃ - (M(q) - M(q̃)) v̇̃.
    f_const = jnp.zeros_like(q)
    if nb and ops.G is None:
        f_const = f_const + (G[:nb] - _bilateral_jacobian(model, smooth.q)).T @ smooth.lam
    if not model.constant_mass:
        f_const = f_const - (model.mass_product(q, smooth.vd) - model.mass_product(smooth.q, smooth.vd))
    if not model.velocity_dependent_force:  # f(q, v) - f(q̃, ṽ) does not change with W
        f_const = f_const + _force_change(model, q, smooth.v, f_smooth, t)

    def residual(x):
        W, Lam = x
        v = smooth.v + W
        gdot = G @ v + restituted
        f_star = f_const
        if model.velocity_dependent_force:
            f_star = f_star + _force_change(model, q, v, f_smooth, t)
        res = _augmented_residual(
            model.mass_product(q, W), h * f_star, G, gdot, Lam, kv, pv,
            position.active, unilateral, tol_r, tol_f,
        )
        return res._replace(aux=res.aux + (gdot,))

    def update(x, res):
        W, Lam = x
        active = res.aux[0]
        v = smooth.v + W
        _, C, K_norm, C_norm = _tangents(model, ops, q, v, t)
        floor = _floor(h, K_norm, C_norm, q, v)
        if ops.velocity_inv is not None:
            solve = inverse_solve(ops.velocity_inv)
        else:
            solve = dense_solve(_mass(model, ops, q) + h * C)
        n = model.n_dof
        dW, dLam = solve_bordered(
            solve, res.r[:n], res.r[n:], G, G, active, kv, pv, ops.velocity_inv_Gt
        )
        return (dW, dLam), floor

    x0 = (jnp.zeros_like(q), jnp.zeros((nc,), q.dtype))
    sol = newton(residual, update, x0, max_iter)
    active, sigma, gdot = sol.aux
    W, _ = sol.x
    return VelocityJump(W=W, impulse=jnp.where(active, sigma, 0.0), active=active, gdot=gdot, newton=sol)


# ------------------------------------------------------------------------ scheme


def _result_code(results: list[NewtonResult]) -> jax.Array:
    """First failing sub-problem wins; non-finite beats iteration cap."""
    code = jnp.int8(Result.successful)
    for i in reversed(range(len(results))):
        r = results[i]
        nonfinite = ~jnp.isfinite(r.residual_norm)
        failed = ~r.converged
        this = jnp.where(nonfinite, jnp.int8(4 + i), jnp.int8(1 + i))
        code = jnp.where(failed, this, code)
    return code



class DS(eqx.Module):
    """Decoupled nonsmooth generalized-α (paper §3.3, Algorithm 1).

    Attributes:
        rho_inf: spectral radius at infinity ρ∞ ∈ [0, 1] (eq. 35).
        tol_r, tol_f: relative and reference tolerances of eq. 51.
        max_iter: Newton iteration cap per sub-problem (static).
    """

    rho_inf: ScalarLike = eqx.field(default=0.8, converter=as_float)
    tol_r: ScalarLike = eqx.field(default=1e-5, converter=as_float)
    tol_f: ScalarLike = eqx.field(default=1e-5, converter=as_float)
    max_iter: int = eqx.field(static=True, default=50)

    @property
    def coefficients(self) -> GenAlphaCoefficients:
        return GenAlphaCoefficients.from_rho_inf(self.rho_inf)

    def prepare(self, model: Model, h: Scalar, t0: Scalar) -> Operators:
        """Constant operators for this model and step size (run once, outside the loop)."""
        return prepare(model, self.coefficients, h, t0)

    def init(self, model: Model, t0: Scalar, q0: Vector, v0: Vector) -> StepState:
        """Initial state with a consistent smooth acceleration (Algorithm 1, lines 2-3)."""
        q0 = jnp.asarray(q0, dtype=float)
        v0 = jnp.asarray(v0, dtype=float)
        vd0 = consistent_acceleration(model, t0, q0, v0)
        return StepState(t=jnp.asarray(t0, dtype=float), q=q0, v=v0, vd=vd0, a=vd0)

    def step(self, model: Model, ops: Operators, state: StepState, h: Scalar) -> tuple[StepState, StepOutput]:
        """Advance one step of size h [s]; returns the new state and the step's record."""
        co = self.coefficients
        tol = (jnp.asarray(self.tol_r, float), jnp.asarray(self.tol_f, float), self.max_iter)
        nb, nc = model.n_bilateral, model.n_constraints
        t = state.t + h

        # 0. predictor (Algorithm 1, lines 5-9)
        a_pred = (co.alpha_f * state.vd - co.alpha_m * state.a) / (1.0 - co.alpha_m)
        v_pred = state.v + h * (1.0 - co.gamma) * state.a + h * co.gamma * a_pred
        q_pred = state.q + h * state.v + h**2 * (0.5 - co.beta) * state.a + h**2 * co.beta * a_pred

        # 1. smooth motion
        smooth = smooth_motion(model, ops, co, tol, t, h, q_pred, v_pred)
        newton_results = [smooth.newton]

        if nc == 0:  # nothing to project: U = W = 0 exactly
            q, v = smooth.q, smooth.v
            empty = jnp.zeros((0,), q.dtype)
            nu = impulse = gap = bil = bil_rate = empty
            act_p = act_v = jnp.zeros((0,), bool)
            iters = [smooth.newton.iterations, jnp.int32(0), jnp.int32(0)]
            resid = [smooth.newton.residual_norm, jnp.zeros(()), jnp.zeros(())]
            tols = [smooth.newton.tolerance, jnp.zeros(()), jnp.zeros(())]
        else:
            f_smooth = model.force(smooth.q, smooth.v, t)
            # 2. position correction (never sees W)
            position = position_correction(model, ops, tol, t, h, smooth, f_smooth)
            # 3. velocity jump
            G_prev_v_prev = _jacobian(model, ops, state.q) @ state.v
            velocity = velocity_jump(model, ops, tol, t, h, smooth, f_smooth, position, G_prev_v_prev)
            newton_results += [position.newton, velocity.newton]
            q = smooth.q + position.U
            v = smooth.v + velocity.W
            nu, impulse = position.nu, velocity.impulse
            gap, bil = position.g[nb:], position.g[:nb]
            bil_rate = velocity.gdot[:nb]
            act_p, act_v = position.active, velocity.active
            iters = [r.iterations for r in newton_results]
            resid = [r.residual_norm for r in newton_results]
            tols = [r.tolerance for r in newton_results]

        # 4. finalise (Algorithm 1, line 41)
        a = a_pred + co.a_per_vd() * smooth.vd
        new_state = StepState(t=t, q=q, v=v, vd=smooth.vd, a=a)
        out = StepOutput(
            t=t,
            q=q,
            v=v,
            lam=smooth.lam,
            nu=nu,
            impulse=impulse,
            gap=gap,
            bilateral=bil,
            bilateral_rate=bil_rate,
            active_position=act_p,
            active_velocity=act_v,
            iterations=jnp.stack(iters).astype(jnp.int32),
            residual=jnp.stack(resid),
            tolerance=jnp.stack(tols),
            result=_result_code(newton_results),
        )
        return new_state, out

