"""The Newton loop: modified Newton from a held factorisation refactors only
when an update converges too slowly, and gives what Newton's method gives."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import spd_system

import nsga_jax
from nsga_jax import simulate
from nsga_jax._integrators.linalg import Factorisation
from nsga_jax._integrators.newton import Problem, Residual, newton, where_needed
from nsga_jax.scenes import REGISTRY, load_scene, make_scheme, parametrize

N = 6
A, RHS = spd_system(N, seed=3)
TOL = 1e-12


def cubic(strength: float) -> Problem:
    """r(x) = A x + strength x³ - b, with its exact Jacobian."""

    def residual(x):
        r = A @ x + strength * x**3 - RHS
        return Residual(r, jnp.asarray(TOL), None)

    def linearise(x, res):
        return Factorisation.of(A + jnp.diag(3 * strength * x**2), jnp.zeros(()), jnp.zeros(()))

    def correct(x, res, fac):
        return -fac.solve(res.r), jnp.zeros(())

    return Problem(residual, linearise, correct)


def run(problem, held=None, max_iter=50):
    return jax.jit(lambda h: newton(problem, jnp.zeros(N), max_iter, h))(held)


def test_modified_newton_finds_newtons_root_without_refactoring():
    problem = cubic(0.05)
    exact = run(problem)
    held = problem.linearise(jnp.zeros(N), None)
    reused = run(problem, held)
    assert exact.converged and reused.converged
    np.testing.assert_allclose(reused.x, exact.x, atol=1e-12)
    assert reused.iterations > exact.iterations  # linear, not quadratic, convergence ...
    np.testing.assert_array_equal(reused.factorisation.lu, held.lu)  # ... with the matrix it was given


def test_modified_newton_factors_when_it_holds_nothing():
    problem = cubic(0.05)
    sol = run(problem, Factorisation.empty(N, jnp.float64))
    assert sol.converged and bool(sol.factorisation.valid)
    # factored once, at the starting point
    np.testing.assert_allclose(sol.factorisation.lu, problem.linearise(jnp.zeros(N), None).lu)


def test_a_poor_factorisation_is_replaced():
    problem = cubic(0.05)
    poor = Factorisation.of(10.0 * A, jnp.zeros(()), jnp.zeros(()))  # updates 10 times too short
    sol = run(problem, poor)
    assert sol.converged
    np.testing.assert_allclose(sol.x, run(problem).x, atol=1e-12)
    assert not np.allclose(sol.factorisation.lu, poor.lu)


def test_a_diverging_update_is_discarded():
    """With a factorisation of the wrong sign, the first update grows the
    residual: it is discarded and the matrix refactored at the same (starting)
    iterate, which then serves to the end."""
    problem = cubic(0.05)
    wrong = Factorisation.of(-A, jnp.zeros(()), jnp.zeros(()))
    sol = run(problem, wrong)
    assert sol.converged
    np.testing.assert_allclose(sol.x, run(problem).x, atol=1e-12)
    np.testing.assert_allclose(sol.factorisation.lu, problem.linearise(jnp.zeros(N), None).lu)
    assert sol.iterations == run(problem, problem.linearise(jnp.zeros(N), None)).iterations + 1


@pytest.mark.parametrize("name", sorted(REGISTRY))
def test_reused_subproblems_are_those_left_non_constant(name):
    """A scheme holds a factorisation exactly for the sub-problems whose
    iteration matrix ``prepare`` does not invert once."""
    scene = load_scene(name)
    for scheme in (nsga_jax.DS(reuse_min_dof=0), nsga_jax.DSn(reuse_min_dof=0)):
        ops = scheme.prepare(scene.model, 1e-3, 0.0)
        constant = (ops.smooth.is_constant, ops.position.is_constant, ops.velocity.is_constant)
        has_jumps = scene.model.n_constraints > 0
        expected = (not constant[0], has_jumps and not constant[1], has_jumps and not constant[2])
        assert scheme.reused(scene.model) == expected
        state = scheme.init(scene.model, 0.0, scene.q0, scene.v0)
        if any(expected):
            assert [f is not None for f in state.factorisations] == list(expected)
        else:
            assert state.factorisations is None
    assert dataclasses.replace(nsga_jax.DS(reuse_min_dof=0), fast_paths=False).reused(scene.model) == (False,) * 3


KINDS = {  # the DS iteration matrices (smooth, position, velocity) each scene's structure gives
    "impacting_bar": ("ConstantTridiagonal",) * 3,  # linear chain of half-bandwidth 1, affine contact
    "bouncing_ball": ("ConstantInverse",) * 3,
    "rigid_box": ("Refactored", "Refactored", "ConstantInverse"),  # curved joints: M + h C is still constant
    "rigid_pendulum": ("Refactored", "Refactored", "ConstantInverse"),
    "flexible_pendulum": ("Refactored",) * 3,  # nonlinear beam of 27 coordinates
    # a matrix-free solid of at least krylov_min_dof coordinates: blocks held, the velocity jump's c_m M constant
    "flexible_cube": ("KrylovHeld", "KrylovHeld", "KrylovConstant"),
    "newtons_cradle": ("ConstantInverse",) * 3,  # point masses on a line, affine contacts
    "double_pendulum": ("Refactored", "Refactored", "ConstantInverse"),  # pins on rotating rods
    "slider_crank": ("Refactored",) * 3,  # flexible rod: M + h C changes with the beam's tangents
    "flexible_appendage": ("Refactored",) * 3,
    # planar rigid bodies: constant mass, no joints, but corners that turn with θ (nonlinear contacts)
    "incline": ("ConstantInverse", "Refactored", "ConstantInverse"),
    "rocking_block": ("ConstantInverse", "Refactored", "ConstantInverse"),
    "box_stack": ("ConstantInverse", "Refactored", "ConstantInverse"),  # planar boxes, face contacts that turn
}


@pytest.mark.parametrize("name", sorted(REGISTRY))
def test_each_scene_gets_the_iteration_matrices_of_its_structure(name):
    """The kinds are static: read from the scheme without evaluating anything,
    they are those ``prepare`` builds; the generic path refactors everything."""
    scene = load_scene(name)
    scheme = nsga_jax.DS()
    kinds = scheme.matrix_kinds(scene.model)
    assert tuple(kind.__name__ for kind in kinds) == KINDS[name]
    ops = scheme.prepare(scene.model, 1e-3, 0.0)
    assert tuple(type(m) for m in (ops.smooth, ops.position, ops.velocity)) == kinds
    assert scheme.reused(scene.model) == tuple(kind.is_held for kind in kinds)
    assert ops.mass.is_constant == scene.model.constant_mass
    assert ops.force.is_constant == scene.model.linear_force
    assert ops.constraints.is_constant == scene.model.linear_constraints
    generic = dataclasses.replace(scheme, fast_paths=False)
    assert {kind.__name__ for kind in generic.matrix_kinds(scene.model)} == {"Refactored"}


def test_reuse_gives_the_trajectory_of_newtons_method():
    """Rigid box (contacts, a non-constant mass): with factorisations reused
    between iterations and steps, at a tight tolerance, the trajectory and
    active sets are those of a fresh factorisation at every iteration."""
    scene = load_scene("rigid_box", {"t_end": 0.3})
    base = dataclasses.replace(scene.scheme(), tol_r=1e-10, tol_f=1e-10)
    args = (0.0, scene.solver["t_end"], scene.solver["h"], scene.q0, scene.v0)
    reused = simulate(scene.model, dataclasses.replace(base, reuse_min_dof=0), *args)
    fresh = simulate(scene.model, dataclasses.replace(base, reuse_min_dof=10**9), *args)
    assert len(reused.failed_steps) == len(fresh.failed_steps) == 0
    assert reused.records.active_velocity.any()
    np.testing.assert_array_equal(reused.records.active_velocity, fresh.records.active_velocity)
    for x, y in ((reused.q, fresh.q), (reused.v, fresh.v)):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-8 * np.abs(y).max())


def test_gradients_with_reused_factorisations():
    """The implicit derivative is built at x* with a fresh matrix, so reusing
    factorisations in the iterations leaves the gradient unchanged (at a tight
    tolerance: x*, and so the gradient, follow the Newton tolerance)."""
    overrides = {"h": 1e-3}
    scene = load_scene("rigid_pendulum", overrides)
    params, build = parametrize("rigid_pendulum", overrides, ["length"])
    grads = []
    for min_dof in (0, 10**9):
        scheme = dataclasses.replace(make_scheme(scene.solver), reuse_min_dof=min_dof, tol_r=1e-10, tol_f=1e-10)

        def loss(p, scheme=scheme):
            model, q0, v0, observables = build(p)
            sol = nsga_jax.integrate(model, scheme, 0.0, 1.5, 1e-3, q0, v0)
            return jnp.mean(observables(sol)["x"] ** 2)

        grads.append(float(jax.jit(jax.grad(loss))(params)["length"]))
    assert abs(grads[1]) > 1e-8
    np.testing.assert_allclose(grads[0], grads[1], rtol=1e-6)


def counting(fn, calls: list):
    """``fn`` that appends to ``calls`` whenever it is evaluated (at run time)."""

    def counted(*args):
        jax.debug.callback(lambda: calls.append(1))
        return fn(*args)

    return counted


def test_where_needed_evaluates_only_when_a_member_needs_it():
    calls = []
    double = counting(lambda x: 2 * x, calls)
    batched = jax.jit(jax.vmap(lambda p, x: where_needed(p, lambda: double(x), x)))
    x = jnp.arange(3.0)
    np.testing.assert_array_equal(batched(jnp.array([False, False, False]), x), x)
    assert calls == []  # a select of both branches would have evaluated it
    np.testing.assert_array_equal(batched(jnp.array([False, True, False]), x), [0.0, 2.0, 2.0])
    assert calls  # evaluated, and kept for member 1 only
    calls.clear()
    alone = jax.jit(lambda p, x: where_needed(p, lambda: double(x), x))
    assert float(alone(False, 1.5)) == 1.5 and calls == []
    assert float(alone(True, 1.5)) == 3.0 and calls


def test_a_batch_holding_good_factorisations_never_refactors():
    """vmap over members of a modified Newton solve: held factorisations that
    serve every member are never replaced, and nothing is refactored (the
    refactoring branch is skipped, not computed and discarded)."""
    strengths = jnp.array([0.02, 0.05])
    calls = []

    def problem(strength):
        p = cubic(strength)
        return p._replace(linearise=counting(p.linearise, calls))

    held = cubic(0.0).linearise(jnp.zeros(N), None)
    solve = jax.jit(jax.vmap(lambda s: newton(problem(s), jnp.zeros(N), 50, held)))
    sol = solve(strengths)
    assert bool(sol.converged.all()) and calls == []
    for k, s in enumerate(strengths):
        np.testing.assert_allclose(sol.x[k], run(cubic(float(s))).x, atol=1e-12)
    poor = jax.jit(jax.vmap(lambda s, f: newton(problem(s), jnp.zeros(N), 50, f)))
    factors = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), held,
                                     Factorisation.of(10.0 * A, jnp.zeros(()), jnp.zeros(())))
    sol = poor(strengths, factors)
    assert bool(sol.converged.all()) and calls
    np.testing.assert_array_equal(sol.factorisation.lu[0], held.lu)  # member 0 kept its good one
    assert not np.allclose(sol.factorisation.lu[1], 10.0 * A)


def test_a_batch_with_held_factorisations_equals_single_runs():
    """Rigid boxes with different restitutions, factorisations held (their
    contacts, and so their refactorings, come at different steps): the batch
    gives each member's single run."""
    from nsga_jax._batch import BatchRun, stack_models

    settings = {"z0": 0.3, "t_end": 0.2, "h": 2e-3}
    scenes = [load_scene("rigid_box", {**settings, "e": e}) for e in (0.2, 0.9)]
    scheme = dataclasses.replace(scenes[0].scheme(), reuse_min_dof=0)
    n = 100
    run = BatchRun(stack_models([s.model for s in scenes]), scheme, 0.0, np.stack([s.q0 for s in scenes]),
                   np.stack([s.v0 for s in scenes]), np.full(2, 2e-3), np.full(2, n))
    q = np.concatenate([out.q for out, _ in run.chunks()], axis=1)
    for k, scene in enumerate(scenes):
        single = simulate(scene.model, scheme, 0.0, 0.2, 2e-3, scene.q0, scene.v0)
        assert single.records.active_velocity.any()
        np.testing.assert_allclose(q[k, :n], single.q[1:], rtol=0, atol=1e-9 * np.abs(single.q).max())


def arctan_root(scale, restart_to=None, root=0.0) -> Problem:
    """r(x) = scale · arctan((x - root) / scale), root x = ``root`` for every
    scale: Newton from |(x0 - root) / scale| > 1.39 runs away (its updates
    overshoot ever more), nearer it converges; the problems of two scales are
    two forms of one."""

    def residual(x):
        return Residual(scale * jnp.arctan((x - root) / scale), jnp.asarray(TOL), None)

    def update(x, res):
        return -res.r * (1.0 + ((x - root) / scale) ** 2), jnp.zeros(())

    problem = Problem.from_update(residual, update)
    if restart_to is None:
        return problem
    # restart(f): the scale times f, f = 1 first, then restart_to / scale
    return problem._replace(restart=lambda f: arctan_root(f * scale, root=root),
                            restart_factors=(restart_to / scale,))


def test_a_stalled_problem_is_restarted_in_its_other_form():
    x0 = jnp.full((1,), 1.5)
    alone = newton(arctan_root(1.0), x0, 20)
    assert not alone.converged
    other = newton(arctan_root(5.0), x0, 20)
    assert other.converged
    restarted = jax.jit(lambda x: newton(arctan_root(1.0, 5.0), x, 20))(x0)
    assert restarted.converged
    np.testing.assert_array_equal(restarted.x, other.x)  # the second run, from the same start
    assert restarted.iterations == alone.iterations + other.iterations
    # a problem that converges is solved as it was: the restart is never run
    near = jnp.full((1,), 0.5)
    plain = newton(arctan_root(1.0), near, 20)
    with_restart = newton(arctan_root(1.0, 5.0), near, 20)
    assert plain.converged and with_restart.iterations == plain.iterations
    np.testing.assert_array_equal(with_restart.x, plain.x)


def test_the_derivative_of_a_restarted_solve_is_the_roots():
    """Through :func:`solve`'s implicit derivative: the root θ found by the
    restart has dx*/dθ = 1."""
    from nsga_jax._integrators.newton import solve

    def builder(theta):
        return arctan_root(1.0, 5.0, root=theta)

    def root(theta):
        sol = solve(builder, theta, jnp.full((1,), 1.5), 20)
        return sol.x[0], sol.iterations

    (x, iterations), grad = jax.jit(jax.value_and_grad(root, has_aux=True))(jnp.asarray(0.1))
    alone = newton(arctan_root(5.0, root=0.1), jnp.full((1,), 1.5), 20)
    assert iterations > alone.iterations  # the first form ran away from x0 = 1.5: found by the restart
    np.testing.assert_allclose(x, 0.1, atol=1e-12)
    np.testing.assert_allclose(grad, 1.0, rtol=1e-12)
