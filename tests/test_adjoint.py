"""The implicit derivative of a Newton solve (a custom JVP that the primal never
evaluates) and the adjoint objects of a differentiable run."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import spd_system
from jax.extend import core as jcore
from reference_models import BouncingBall

import nsga_jax as nj
from nsga_jax._integrators.linalg import Factorisation
from nsga_jax._integrators.newton import Problem, Residual, newton, solve

N = 5
A, RHS = spd_system(N, seed=7)
TOL = 1e-13
WRAPPERS = {"custom_jvp_call", "pjit", "jit", "closed_call"}


def cubic(strength, rhs) -> Problem:
    """r(x) = A x + strength x³ - rhs, with its exact Jacobian; aux = strength x³."""

    def residual(x):
        cubed = strength * x**3
        return Residual(A @ x + cubed - rhs, jnp.asarray(TOL), cubed)

    def linearise(x, res):
        return Factorisation.of(A + jnp.diag(3 * strength * x**2), jnp.zeros(()), jnp.zeros(()))

    def correct(x, res, fac):
        return -fac.solve(res.r), jnp.zeros(())

    return Problem(residual, linearise, correct)


def root(strength, rhs=RHS, held=None):
    return solve(lambda inputs: cubic(*inputs), (strength, rhs), jnp.zeros(N), 50, held)


root_x = jax.jit(lambda s: root(s).x)


def equations(jaxpr) -> int:
    """Equations of a jaxpr and its sub-jaxprs, call wrappers not counted."""
    n = 0
    for eqn in jaxpr.eqns:
        n += eqn.primitive.name not in WRAPPERS
        for p in eqn.params.values():
            for sub in p if isinstance(p, (list, tuple)) else [p]:
                if isinstance(sub, (jcore.ClosedJaxpr, jcore.Jaxpr)):
                    n += equations(getattr(sub, "jaxpr", sub))
    return n


@pytest.mark.parametrize("held", [None, Factorisation.empty(N, jnp.float64)], ids=["newton", "modified"])
def test_the_primal_is_newton_alone(held):
    # no Newton correction, no residual or matrix at x*: the derivative is never built
    alone = jax.make_jaxpr(lambda s: newton(cubic(s, RHS), jnp.zeros(N), 50, held))(0.3)
    wrapped = jax.make_jaxpr(lambda s: root(s, held=held))(0.3)
    assert equations(wrapped.jaxpr) == equations(alone.jaxpr)
    np.testing.assert_array_equal(jax.jit(lambda s: root(s, held=held).x)(0.3),
                                  jax.jit(lambda s: newton(cubic(s, RHS), jnp.zeros(N), 50, held).x)(0.3))


def implicit(strength):
    """dx*/dstrength and dx*/drhs by the implicit function theorem."""
    x = np.asarray(root_x(strength))
    J = np.asarray(A) + np.diag(3 * strength * x**2)
    return -np.linalg.solve(J, x**3), np.linalg.inv(J)


@pytest.mark.parametrize("held", [None, Factorisation.empty(N, jnp.float64)], ids=["newton", "modified"])
def test_forward_and_reverse_give_the_implicit_derivative(held):
    d_strength, d_rhs = implicit(0.3)

    @jax.jit
    def derivatives(s, b):
        fwd = jax.jacfwd(lambda s, b: root(s, b, held).x, argnums=(0, 1))(s, b)
        rev = jax.jacrev(lambda s, b: root(s, b, held).x, argnums=(0, 1))(s, b)
        return fwd, rev, jax.jacfwd(lambda s: root(s, b, held).aux)(s)

    fwd, rev, aux = derivatives(0.3, RHS)
    for got in (fwd, rev):
        np.testing.assert_allclose(got[0], d_strength, rtol=1e-10)
        np.testing.assert_allclose(got[1], d_rhs, rtol=1e-10, atol=1e-14)
    # the aux follows x* and the parameters: d(s x³)/ds = x³ + 3 s x² dx/ds
    x = np.asarray(root_x(0.3))
    np.testing.assert_allclose(aux, x**3 + 0.9 * x**2 * d_strength, rtol=1e-10)


def test_vmap_of_grad_equals_a_loop_of_grads():
    def loss(s):
        sol = root(s, held=Factorisation.empty(N, jnp.float64))
        return jnp.sum(sol.x**2) + sol.factorisation.lu.sum() * 0.0  # the held factors have zero tangents

    strengths = jnp.array([0.1, 0.3, 0.7])
    batched = jax.jit(jax.vmap(jax.grad(loss)))(strengths)
    grad = jax.jit(jax.grad(loss))
    for k, s in enumerate(strengths):
        np.testing.assert_allclose(batched[k], grad(s), rtol=1e-12)
        x = np.asarray(root_x(s))
        np.testing.assert_allclose(batched[k], 2 * x @ implicit(s)[0], rtol=1e-10)


def ball():
    return BouncingBall(m=1.0, gravity=9.81, e=0.5), jnp.ones(1), jnp.zeros(1)


@pytest.mark.parametrize("adjoint", [nj.DiscreteAdjoint(), nj.ImpactTimeAdjoint()], ids=["discrete", "event"])
def test_an_adjoint_steps_the_scheme(adjoint):
    model, q0, v0 = ball()
    scheme = nj.DS()
    h = jnp.asarray(1e-3)
    ops = eqx.filter_jit(scheme.prepare)(model, h, jnp.asarray(0.0))
    state = scheme.init(model, 0.0, q0, v0)
    extra = adjoint.init(model, q0)
    new, out, extra_new = eqx.filter_jit(adjoint.step)(scheme, model, ops, state, extra, h)
    expected, expected_out = eqx.filter_jit(scheme.step)(model, ops, state, h)
    np.testing.assert_array_equal(new.q, expected.q)
    np.testing.assert_array_equal(out.v, expected_out.v)
    assert jax.tree_util.tree_structure(extra_new) == jax.tree_util.tree_structure(extra)
    with pytest.raises(nj.ConfigError, match="CS is not differentiable"):
        adjoint.step(nj.CS(), model, ops, state, extra, h)


def test_adjoints_carry_what_they_need():
    model, q0, _ = ball()
    assert nj.DiscreteAdjoint().init(model, q0) == ()
    active = nj.ImpactTimeAdjoint().init(model, q0)
    assert active.shape == (model.n_unilateral,) and active.dtype == bool and not bool(active[0])
    assert bool(nj.ImpactTimeAdjoint().init(model, jnp.zeros(1))[0])  # touching at t0: not closing
