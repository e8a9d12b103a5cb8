"""Failures are named (step, time, sub-problem, residual), never silent NaNs."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import Oscillator

import nsga_jax as nj
from nsga_jax.scenes import load_scene


def test_iteration_cap_raises_a_named_error():
    scene = load_scene("rigid_pendulum", {"max_iter": 1, "t_end": 2.0})
    with pytest.raises(nj.ConvergenceError) as info:
        scene.run()
    err = info.value
    assert err.result == nj.Result.position_max_iter
    assert "position correction" in str(err) and f"step {err.step}" in str(err)
    assert err.time == pytest.approx(err.step * 1e-3)
    assert err.residual > err.tolerance
    # the run stopped there: the partial solution ends at the failed step
    assert err.solution.n_steps == err.step
    assert err.solution.failed_steps.tolist() == [err.step]


def test_no_throw_marks_failed_steps_and_goes_on():
    scene = load_scene("rigid_pendulum", {"max_iter": 1, "t_end": 2.0})
    sol = scene.run(throw=False)
    assert sol.n_steps == 2000
    failed = sol.failed_steps
    assert failed.size > 0 and sol.stats["failed_steps"] == failed.size
    assert np.all(np.asarray(sol.records.result)[failed] == nj.Result.position_max_iter)
    assert sol.result == nj.Result.position_max_iter


class Blowup(Oscillator):
    """An oscillator whose force becomes NaN after t = 0.05 s."""

    def force(self, q, v, t):
        return jnp.where(t > 0.05, jnp.nan, -self.k * q)


def test_nan_is_reported_at_the_step_it_appears():
    model = Blowup(m=1.0, k=1.0)
    with pytest.raises(nj.ConvergenceError, match="non-finite value") as info:
        nj.simulate(model, nj.DS(), 0.0, 1.0, 0.01, [1.0], [0.0])
    assert info.value.result == nj.Result.smooth_nonfinite
    assert info.value.step == 6 and info.value.time == pytest.approx(0.06)
    sol = nj.simulate(model, nj.DS(), 0.0, 1.0, 0.01, [1.0], [0.0], throw=False)
    assert sol.failed_steps[0] == 6 and sol.stats["failed_steps"] == 95
    assert np.all(np.isfinite(sol.q[:6]))


class HalfMassless(nj.Model):
    """Two coordinates, the second with neither mass nor stiffness: M is singular."""

    m: jax.Array
    n_dof = 2
    constant_mass = True
    linear_force = True
    linear_constraints = True
    mbar = 1.0

    def mass(self, q):
        return jnp.diag(jnp.stack([self.m, 0.0 * self.m]))

    def force(self, q, v, t):
        return jnp.stack([-9.81 * self.m, 0.0 * self.m])


@pytest.mark.parametrize("fast_paths", [True, False])
def test_a_singular_matrix_is_named_as_the_cause(fast_paths):
    with pytest.raises(nj.ConvergenceError, match="non-finite value") as info:
        nj.simulate(HalfMassless(m=jnp.asarray(1.0)), nj.DS(fast_paths=fast_paths), 0.0, 0.01, 1e-3,
                    [1.0, 0.0], [0.0, 0.0])
    err = info.value
    assert err.step == 1 and err.result == nj.Result.smooth_nonfinite
    message = str(err)
    assert "Before the first step" in message and "initial acceleration is not finite" in message
    # the fast path inverted the smooth iteration matrix once, the generic one never
    assert ("inverted iteration matrix of the smooth motion sub-problem" in message) == fast_paths


def test_a_failure_after_a_finite_start_gets_no_singular_matrix_hint():
    with pytest.raises(nj.ConvergenceError) as info:
        nj.simulate(Blowup(m=1.0, k=1.0), nj.DS(), 0.0, 1.0, 0.01, [1.0], [0.0])
    assert "Before the first step" not in str(info.value)


def test_a_singular_block_of_the_tridiagonal_elimination_is_named():
    import dataclasses

    from nsga_jax._integrators.base import StepState
    from nsga_jax._integrators.iteration_matrix import ConstantTridiagonal
    from nsga_jax._integrators.linalg import Tridiagonal
    from nsga_jax._integrators.operators import generic_operators
    from nsga_jax._simulate import nonfinite_origin

    n = 11
    band = jnp.stack([jnp.full(n, -1.0), jnp.full(n, 2.0), jnp.full(n, -1.0)])
    singular = Tridiagonal.of(band.at[:, :4].set(0.0))  # the first block is all zero
    assert not np.all(np.isfinite(np.asarray(singular.blocks_inv)))
    nothing = generic_operators()  # no constant operator
    zero = jnp.zeros(())
    state = StepState(t=jnp.zeros(()), q=jnp.zeros(n), v=jnp.zeros(n), vd=jnp.zeros(n), a=jnp.zeros(n))
    assert nonfinite_origin(nothing, state) == ""
    position = ConstantTridiagonal(elimination=singular, inverse_Gt=None, K_norm=zero, C_norm=zero)
    hint = nonfinite_origin(dataclasses.replace(nothing, position=position), state)
    assert "inverted iteration matrix of the position correction" in hint and "singular" in hint
    assert "initial acceleration" not in hint
