"""Failures are named (step, time, sub-problem, residual), never silent NaNs."""

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
