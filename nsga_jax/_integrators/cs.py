"""The original coupled nonsmooth generalized-α scheme (CS) of Brüls, Acary and
Cardona (2014), as the paper describes it (§3.3.6 and §4).

The smooth equation is evaluated at the *total* motion, M(q) v̇̃ - g_q^T λ̃ =
f(q, v, t) with q = q̃ + U and v = ṽ + W, with the bilateral velocity
constraint on ṽ at q; the jump equations carry no f terms (eqs. 31a-b). All
unknowns are iterated together with a Jacobian that keeps only the three
diagonal blocks (the coupling of the smooth block to U and W is neglected):
each global iteration is three linear solves, smooth, position, velocity, in
Gauss–Seidel order, until all three residuals pass eq. 51. The step's
iteration count is its number of linear solves, as in the paper. A divergent
iteration (residual growing without bound, or non-finite) and the iteration cap
are reported per step by a result code.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax

from .._custom_types import Scalar
from .._models.base import Model
from .._results import RESULTS, from_code
from .base import (
    StepState,
)
from .contact_rows import projection_start
from .ds import DS, AbstractGenAlpha
from .operators import MatrixKinds, Operators, matrix_kinds, prepare_operators
from .records import NewtonRecord, PositionAux, StepOutput, SubproblemRecord, VelocityAux, make_output
from .residuals import DIVERGENCE_FACTOR
from .subproblem_inputs import PositionInputs, SmoothInputs, StepInputs, VelocityInputs
from .subproblems import (
    position_problem,
    smooth_motion,
    smooth_problem,
    smooth_start,
    velocity_problem,
)


def _add(x, dx):
    return jax.tree_util.tree_map(jnp.add, x, dx)


class CS(AbstractGenAlpha):
    """Coupled nonsmooth generalized-α (the original NSGA).

    Attributes:
        rho_inf: spectral radius at infinity ρ∞ ∈ [0, 1] (eq. 35).
        tol_r, tol_f: tolerances of eq. 51, applied to each of the three residuals.
        max_iter: cap on the global iterations (each is three linear solves). Static.
        krylov_min_dof: as :attr:`~nsga_jax.DS.krylov_min_dof` (the three
            diagonal blocks as element blocks, solved by conjugate gradients). Static.
    """

    name = "cs"
    subproblems = ("coupled",)

    def prepare(self, model: Model, h: Scalar, t0: Scalar) -> Operators:
        co = self.coefficients
        c_vd, c_q = co.vd_per_v(h), co.q_per_v(h)
        return prepare_operators(
            model, t0, self.matrix_kinds(model),
            (lambda M, K, C: c_vd * M + C + c_q * K, lambda M, K, C: M, lambda M, K, C: M),
            enabled=self.fast_paths, tol_r=self.tol_r,
        )

    def matrix_kinds(self, model: Model) -> MatrixKinds:
        """Constant for a constant mass and a linear force (the smooth and
        position matrices only with affine constraints), else refactored;
        element blocks on the matrix-free path (:meth:`matrix_free`), where
        only the smooth block holds the stiffness (the jumps carry no f terms)."""
        return matrix_kinds(model, needs_constant_G=(True, True, False), enabled=self.fast_paths,
                            krylov=self.matrix_free(model), holds_stiffness=(True, False, False))

    def step(self, model: Model, ops: Operators, state: StepState, h: Scalar) -> tuple[StepState, StepOutput]:
        if model.n_constraints == 0:  # no jumps: CS and DS coincide, the coupled iteration is the smooth one
            new, out = DS(self.tol_r, self.tol_f, self.max_iter, rho_inf=self.rho_inf).step(model, ops, state, h)
            smooth = from_code(out.result)
            result = RESULTS.where(smooth == RESULTS.successful, RESULTS.successful,
                                   RESULTS.where(smooth == RESULTS.smooth_nonfinite, RESULTS.coupled_diverged,
                                                 RESULTS.coupled_max_iter))
            newton = NewtonRecord.of(self.subproblems, {"coupled": out.newton["smooth"]}, new.q.dtype)
            return new, make_output(model, out.t, out.q, out.v, out.lam, newton, result)
        tol = self.tolerances
        co = self.coefficients
        t = state.t + h
        a_pred, v_pred, q_pred = self.predict(state, h)
        G_prev_v_prev = ops.constraints.jacobian(model, state.q) @ state.v

        step = StepInputs(model, ops, tol, t, h)  # what every sub-problem is given

        def smooth_res(xs, xp, xv):
            return smooth_problem(SmoothInputs(**step.shared(), co=co, q_pred=q_pred, v_pred=v_pred,
                                               offset=(xp[0], xv[0])))

        def as_smooth(xs):
            return smooth_motion(co, h, q_pred, v_pred, xs, jnp.zeros((model.n_bilateral,), q_pred.dtype))

        def position_res(xs):
            return position_problem(PositionInputs(**step.shared(), smooth=as_smooth(xs), f_smooth=None,
                                                   with_forces=False, q_prev=state.q))

        def velocity_res(xs, xp, candidates):
            return velocity_problem(VelocityInputs(**step.shared(), smooth=as_smooth(xs), U=xp[0],
                                                   candidates=candidates, f_smooth=None,
                                                   G_prev_v_prev=G_prev_v_prev, with_forces=False))

        def residuals(xs, xp, xv):
            rp = position_res(xs).residual(xp)
            return smooth_res(xs, xp, xv).residual(xs), rp, velocity_res(xs, xp, rp.aux.active).residual(xv)

        def norms(rs):
            return jnp.stack([jnp.linalg.norm(r.r) for r in rs])

        def bounds(rs):
            return jnp.stack([r.bound for r in rs])

        x0 = (smooth_start(v_pred, model.n_bilateral), projection_start(model, q_pred),
              projection_start(model, q_pred))
        r0 = residuals(*x0)
        n0 = norms(r0)

        def sweep(carry):
            """One global iteration: Gauss-Seidel over the block-diagonal Jacobian."""
            (xs, xp, xv), (rs, _, _), _, it = carry
            dxs, fs = smooth_res(xs, xp, xv).update(xs, rs)
            xs = _add(xs, dxs)
            position = position_res(xs)
            dxp, fp = position.update(xp, position.residual(xp))
            xp = _add(xp, dxp)
            rp = position.residual(xp)
            velocity = velocity_res(xs, xp, rp.aux.active)
            rv = velocity.residual(xv)
            dxv, fv = velocity.update(xv, rv)
            xv, rv = velocity.advance(xv, dxv, rv)  # damped with friction, as in DS's velocity jump
            rs_new = (smooth_res(xs, xp, xv).residual(xs), rp, rv)
            return (xs, xp, xv), rs_new, jnp.stack([fs, fp, fv]), it + 1

        def status(rs, floors):
            n = norms(rs)
            converged = jnp.all(n < bounds(rs) + floors)
            diverged = ~jnp.all(jnp.isfinite(n)) | jnp.any(n > DIVERGENCE_FACTOR * (n0 + bounds(rs)))
            return converged, diverged

        def cond(carry):
            _, rs, floors, it = carry
            converged, diverged = status(rs, floors)
            return ~converged & ~diverged & (it < self.max_iter)

        with jax.named_scope("coupled"):
            carry = lax.while_loop(cond, sweep, (x0, r0, jnp.zeros(3, q_pred.dtype), jnp.zeros((), jnp.int32)))
        (xs, xp, xv), (rs, rp, rv), floors, it = carry
        converged, diverged = status((rs, rp, rv), floors)
        result = RESULTS.where(converged, RESULTS.successful,
                               RESULTS.where(diverged, RESULTS.coupled_diverged, RESULTS.coupled_max_iter))

        smooth = as_smooth(xs)
        qt, vt, vd = smooth.q, smooth.v, smooth.vd
        U, W = xp[0], xv[0]
        position: PositionAux = rp.aux
        velocity: VelocityAux = rv.aux
        q, v = qt + U, vt + W
        # one coupled iteration: three linear solves per global iteration; its residual is the block
        # furthest from its bound
        residual, bound = norms((rs, rp, rv)), bounds((rs, rp, rv)) + floors
        worst = jnp.argmax(residual / jnp.maximum(bound, jnp.finfo(bound.dtype).tiny))
        newton = NewtonRecord.of(self.subproblems, {"coupled": SubproblemRecord(3 * it, residual[worst], bound[worst])},
                                 q.dtype)
        out = make_output(
            model, t, q, v, rs.aux, newton, result,
            nu=jnp.where(position.active, position.multiplier, 0.0),
            impulse=jnp.where(velocity.active, velocity.multiplier, 0.0), g=position.gap, gdot=velocity.rate,
            active_position=position.active, active_velocity=velocity.active, friction=velocity.friction,
        )
        return self.finalise(t, q, v, vd, a_pred), out
