"""The Moreau–Jean θ-scheme: the classical velocity-level time-stepping baseline.

Per step, with q_{n+1} = q_n + h (θ v_{n+1} + (1-θ) v_n):

    M(q_{n+1}) (v_{n+1} - v_n) - h (θ f(q_{n+1}, v_{n+1}, t_{n+1}) + (1-θ) f(q_n, v_n, t_n))
        = g_q(q_{n+1})^T Λ,
    bilateral: g_q^B v_{n+1} = 0,
    unilateral j with a closed predicted gap, g_j(q_n + h/2 v_n) <= 0:
        0 <= g_q^j v_{n+1} + e_j g_q^j(q_n) v_n  ⊥  Λ_j >= 0,

solved by the same semi-smooth augmented-Lagrangian Newton as the NSGA
sub-problems (σ = kv Λ - pv ġ), and with the same Alart–Curnier Coulomb law
on frictional contacts (:mod:`~nsga_jax._integrators.friction`; the slip
velocity g_T(q_{n+1}) v_{n+1} on the contacts of the closed set).
Constraints are imposed at velocity level only, so position-level
violations (penetration, joint drift) accumulate.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Scalar, ScalarLike, Vector
from .._models.base import Model
from .._util import as_float
from .base import (
    AbstractScheme,
    StepState,
)
from .contact_law import NormalLaw
from .contact_rows import has_friction, projection_start, velocity_rows
from .friction import FrictionLaw, restarted
from .krylov import KRYLOV_KINDS, KRYLOV_MIN_DOF, element_top_left
from .model_terms import convective, curvature, is_unilateral, restitution
from .newton import Problem, Residual, convergence_bound, solve
from .operators import MatrixKinds, Operators, matrix_kinds, prepare_operators, uses_matrix_free
from .records import NewtonRecord, StepOutput, SubproblemRecord, VelocityAux, make_output, subproblem_result
from .residuals import Scaling, constraint_floor, roundoff_floor
from .subproblem_inputs import MoreauJeanInputs


class MJ(AbstractScheme):
    """Moreau–Jean θ-scheme.

    Attributes:
        theta: θ ∈ [0, 1] of the θ-method (0.5 by default).
        tol_r, tol_f, max_iter: as for every scheme (eq. 51 and the Newton cap).
        krylov_min_dof: as :attr:`~nsga_jax.DS.krylov_min_dof`: a
            matrix-free model of at least this many coordinates assembles no
            matrix; its one iteration matrix M + (hθ)² K is element blocks
            solved by conjugate gradients. ``None``: never. Static.
    """

    theta: ScalarLike = eqx.field(default=0.5, converter=as_float, kw_only=True)
    krylov_min_dof: int | None = eqx.field(static=True, default=KRYLOV_MIN_DOF, kw_only=True)

    name = "mj"
    subproblems = ("moreau_jean",)

    def bounds(self):
        return {"theta": (self.theta, 0.0, 1.0)}

    def prepare(self, model: Model, h: Scalar, t0: Scalar) -> Operators:
        th = self.theta
        return prepare_operators(
            model, t0, self.matrix_kinds(model),
            (None, None, lambda M, K, C: M + h * th * C + (h * th) ** 2 * K), enabled=self.fast_paths,
            tol_r=self.tol_r,
        )

    def matrix_kinds(self, model: Model) -> MatrixKinds:
        """One velocity-level matrix: constant for a constant mass, a linear
        force and affine constraints (it holds their curvature), else refactored;
        element blocks on the matrix-free path (:meth:`matrix_free`)."""
        return matrix_kinds(model, needs_constant_G=(False, False, True), present=(False, False, True),
                            enabled=self.fast_paths, krylov=self.matrix_free(model),
                            holds_stiffness=(False, False, True))

    def matrix_free(self, model: Model) -> bool:
        """Whether a run of ``model`` assembles no matrix (static; as :meth:`~nsga_jax.DS.matrix_free`)."""
        return uses_matrix_free(model, self.fast_paths, self.krylov_min_dof)

    def init(self, model: Model, t0: Scalar, q0: Vector, v0: Vector) -> StepState:
        real = jnp.result_type(q0, float)  # the state's precision: q0's (float32 or float64)
        q0 = jnp.asarray(q0, real)
        v0 = jnp.asarray(v0, real)
        zero = jnp.zeros_like(q0)
        return StepState(t=jnp.asarray(t0, real), q=q0, v=v0, vd=zero, a=zero)

    def step(self, model: Model, ops: Operators, state: StepState, h: Scalar) -> tuple[StepState, StepOutput]:
        tol = self.tolerances
        t = state.t + h
        q_n, v_n = state.q, state.v
        f_n = model.force(q_n, v_n, state.t)
        candidates = restituted = None
        if model.n_constraints:
            closing = model.constraints(q_n + 0.5 * h * v_n) <= 0.0
            candidates = ~is_unilateral(model) | closing
            restituted = restitution(model, q_n.dtype) * (ops.constraints.jacobian(model, q_n) @ v_n)
        inputs = MoreauJeanInputs(model, ops, tol, t, h, theta=self.theta, q_n=q_n, v_n=v_n, f_n=f_n,
                                  candidates=candidates, restituted=restituted)
        x0 = (v_n, projection_start(model, v_n)[1])
        sol = solve(moreau_jean_problem, inputs, x0, self.max_iter, name="moreau_jean")
        v, _ = sol.x
        q = q_n + h * (self.theta * v + (1.0 - self.theta) * v_n)
        kwargs = {}
        if model.n_constraints:
            aux: VelocityAux = sol.aux
            kwargs = dict(impulse=jnp.where(aux.active, aux.multiplier, 0.0), gdot=aux.rate,
                          active_velocity=aux.active, friction=aux.friction)
        (name,) = self.subproblems
        newton = NewtonRecord.of(self.subproblems, {name: SubproblemRecord.of(sol)}, q.dtype)
        out = make_output(model, t, q, v, jnp.zeros((model.n_bilateral,), q.dtype), newton,
                          subproblem_result(name, sol), **kwargs)
        zero_n = jnp.zeros_like(q)
        return StepState(t=t, q=q, v=v, vd=zero_n, a=zero_n), out


def moreau_jean_problem(inputs: MoreauJeanInputs) -> Problem:
    """The Moreau–Jean step as a Newton problem on x = (v_{n+1}, Λ):
    ``[M(q)(v - v_n) - h (θ f(q, v) + (1-θ) f_n) - g_q^{B T} σ^B;  -kv ġ^B;  -(kv²/pv) Λ^{B̄}]``,
    q = q_n + h (θ v + (1-θ) v_n), ġ = g_q(q) v + e g_q(q_n) v_n, B = candidates ∩ {σ >= 0};
    with friction, Λ and the residual gain the tangential rows of
    :mod:`~nsga_jax._integrators.friction`."""
    model, ops, tol, t, h, theta = inputs.model, inputs.ops, inputs.tol, inputs.t, inputs.h, inputs.theta
    q_n, v_n, f_n, candidates, restituted = inputs.q_n, inputs.v_n, inputs.f_n, inputs.candidates, inputs.restituted
    tol_r, tol_f, _ = tol
    n, nc = model.n_dof, model.n_constraints
    kv = pv = Scaling.of(model, h).kv
    unilateral = is_unilateral(model)
    friction = has_friction(model)
    law: NormalLaw | FrictionLaw = NormalLaw(candidates, unilateral, kv, pv)
    if friction:  # tangential penalties from the start of the step
        law = FrictionLaw.of(model, candidates, unilateral, kv, pv, ops.mass.diagonal(model, q_n),
                             model.tangent_jacobian(q_n))
    krylov = isinstance(ops.velocity, KRYLOV_KINDS)  # element blocks: constant M, no damping, affine rows

    def build(law: NormalLaw | FrictionLaw) -> Problem:
        """The step with the contact law ``law`` (:func:`~nsga_jax._integrators.friction.restarted`)."""

        def position(v):
            return q_n + h * (theta * v + (1.0 - theta) * v_n)

        def rows(q):
            """g_q(q) (and g_T(q) below it, with friction) and the restitution term of each row."""
            G = ops.constraints.jacobian(model, q)
            if not friction:
                return G, restituted
            G = velocity_rows(model, q, G)
            return G, jnp.concatenate([restituted, jnp.zeros((G.shape[0] - nc,), q.dtype)])

        def residual(x):
            v, Lam = x
            q = position(v)
            inertia = ops.mass.product(model, q, v - v_n)
            force = h * (theta * model.force(q, v, t) + (1.0 - theta) * f_n)
            if nc == 0:
                return Residual(inertia - force, convergence_bound([inertia, force], tol_r, tol_f), ())
            G, e_term = rows(q)
            gdot = G @ v + e_term
            res = law.residual(inertia, force, G, gdot, Lam, tol_r, tol_f)
            active, aug, tangential = res.aux
            return res._replace(aux=VelocityAux(active, aug, gdot[:nc], tangential))

        def update(x, res):
            v, Lam = x
            q = position(v)
            if krylov:  # M + (hθ)² K element by element
                A = ops.velocity.factored(None, lambda: element_top_left(model, ops, q, 1.0, (h * theta) ** 2))
                return correction(x, res, q, A, roundoff_floor(h, A.K_norm, A.C_norm, q, v))
            K, C, K_norm, C_norm = ops.force.tangents(model, q, v, t)
            floor = roundoff_floor(h, K_norm, C_norm, q, v)

            def matrix():  # M + hθ C + (hθ)² K, with the inertia stiffness and the constraint curvature
                A = ops.mass.matrix(model, q) + h * theta * C + (h * theta) ** 2 * K
                A = A + h * theta * model.inertia_stiffness(q, v - v_n)
                if nc:
                    active, sigma = res.aux[0], res.aux[1]
                    A = A - h * theta * curvature(model, q, jnp.where(active, sigma, 0.0))
                if friction and not model.linear_constraints:  # d(g_T^T P_T)/dq
                    A = A - h * theta * jax.jacfwd(lambda y: model.tangent_jacobian(y).T @ res.aux.friction)(q)
                return A, K_norm, C_norm

            return correction(x, res, q, ops.velocity.factored(matrix), floor)

        def correction(x, res, q, A, floor):
            v, Lam = x
            if nc == 0:
                return (-A.solve(res.r), Lam), floor
            G, e_term = rows(q)
            floor = floor + constraint_floor(kv, G, v)
            if krylov:  # affine rows and constant tangents: no convective terms
                dv, dLam = law.correction(A, res.r[:n], res.r[n:], G, G, Lam, G @ v + e_term, None)
                return (dv, dLam), floor
            G_low = G[:nc] + h * theta * convective(model, q, v)
            if friction:  # the tangential rows, with their convective part d(g_T v)/dq
                G_T = G[nc:] if model.linear_constraints else G[nc:] + h * theta * jax.jacfwd(
                    lambda y: model.tangent_jacobian(y) @ v)(q)
                G_low = jnp.concatenate([G_low, G_T])
            dv, dLam = law.correction(A, res.r[:n], res.r[n:], G, G_low, Lam, G @ v + e_term, None)
            return (dv, dLam), floor

        return Problem.from_update(residual, update)._replace(**restarted(law, build))

    return build(law)
