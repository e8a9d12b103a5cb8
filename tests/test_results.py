"""Results as an enumeration (a member per failure, combined inside jit) and
per-step records named by each scheme's own sub-problems."""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
from helpers import Oscillator

import nsga_jax as nj
from nsga_jax._integrators.records import first_failure
from nsga_jax._results import FAILURES, RESULTS, SUBPROBLEM_LABELS, Result, code_of, from_code
from nsga_jax.scenes import load_scene


def test_each_failure_is_a_member_with_its_message():
    for name, message in FAILURES.items():
        member = getattr(RESULTS, name)
        assert RESULTS[member] == message
        host = Result(int(code_of(member)))
        assert host.name == name and host.message == message
        assert host.subproblem in SUBPROBLEM_LABELS
        assert SUBPROBLEM_LABELS[host.subproblem] in message or host.subproblem == "coupled"
    assert Result.position_max_iter.capped and not Result.position_max_iter.nonfinite
    assert Result.smooth_nonfinite.nonfinite and Result.smooth_nonfinite.subproblem == "smooth"
    assert Result.moreau_jean_max_iter.subproblem == "moreau_jean"
    assert Result.successful.message == "successful" and Result.successful.subproblem is None
    # built on optimistix's results: its members keep their meaning and are promoted into ours
    assert RESULTS.promote(optx.RESULTS.nonfinite) == RESULTS.nonfinite
    assert RESULTS.promote(optx.RESULTS.successful) == RESULTS.successful


def test_where_and_first_failure_inside_jit():
    @jax.jit
    def combine(smooth_ok, position_ok, velocity_ok):
        results = [RESULTS.where(smooth_ok, RESULTS.successful, RESULTS.smooth_max_iter),
                   RESULTS.where(position_ok, RESULTS.successful, RESULTS.position_nonfinite),
                   RESULTS.where(velocity_ok, RESULTS.successful, RESULTS.velocity_max_iter)]
        return code_of(first_failure(results))

    t, f = jnp.asarray(True), jnp.asarray(False)
    assert Result(int(combine(t, t, t))) == Result.successful
    assert Result(int(combine(t, f, f))) == Result.position_nonfinite  # the first failing sub-problem
    assert Result(int(combine(f, f, t))) == Result.smooth_max_iter
    assert Result(int(combine(t, t, f))) == Result.velocity_max_iter
    # stored codes decode to members inside jit, and error_if raises the member's message
    codes = jnp.asarray([int(Result.successful), int(Result.coupled_diverged)], jnp.int32)
    failed = jax.jit(lambda c: from_code(c) != RESULTS.successful)(codes)
    np.testing.assert_array_equal(failed, [False, True])
    with pytest.raises(Exception, match="coupled .CS. iteration diverged"):
        jax.block_until_ready(jax.jit(lambda c: from_code(c[1]).error_if(c, jnp.any(c != 0)))(codes))


@pytest.fixture(scope="module")
def ball_runs():
    return {s: load_scene("bouncing_ball", {"scheme": s, "t_end": 0.5}).run() for s in ("ds", "cs", "mj")}


def test_schemes_record_their_own_subproblems(ball_runs):
    expected = {"ds": ("smooth", "position", "velocity"), "cs": ("coupled",), "mj": ("moreau_jean",)}
    for scheme, sol in ball_runs.items():
        names = expected[scheme]
        assert sol.subproblems == names == nj.SCHEMES[scheme].subproblems
        assert sol.iterations.shape == (sol.n_steps + 1, len(names))
        assert set(sol.stats["iterations"]) == {*names, "linear_solves"}
        for i, name in enumerate(names):
            record = sol.newton(name)
            np.testing.assert_array_equal(record.iterations, sol.iterations[:, i])
            assert np.all(record.residual[1:] <= record.tolerance[1:])
    # CS counts the linear solves of its coupled iteration: three per global iteration
    assert np.all(ball_runs["cs"].iterations % 3 == 0) and ball_runs["cs"].iterations.max() >= 3
    with pytest.raises(KeyError, match="moreau_jean"):
        ball_runs["mj"].newton("position")


def test_a_capped_position_subproblem_is_reported_by_name():
    scene = load_scene("rigid_pendulum", {"max_iter": 1, "t_end": 0.7})
    sol = scene.run(throw=False)
    failed = sol.failed_steps
    assert failed.size > 0
    codes = np.asarray(sol.records.result)[failed]
    assert {Result(int(c)).subproblem for c in codes} == {"position"}
    position = sol.newton("position")
    assert np.all(position.iterations[failed] == 1)
    assert np.all(position.residual[failed] > position.tolerance[failed])
    with pytest.raises(nj.ConvergenceError, match="position correction") as info:
        scene.run()
    err = info.value
    assert err.subproblem == "position" and err.residual > err.tolerance
    assert err.residual == sol.newton("position").residual[err.step]


class Blowup(Oscillator):
    """An oscillator whose force becomes NaN after t = 0.05 s."""

    def force(self, q, v, t):
        return jnp.where(t > 0.05, jnp.nan, -self.k * q)


def test_moreau_jean_failures_name_its_own_subproblem():
    with pytest.raises(nj.ConvergenceError, match="Moreau–Jean") as info:
        nj.simulate(Blowup(m=1.0, k=1.0), nj.MJ(), 0.0, 1.0, 0.01, [1.0], [0.0])
    assert info.value.result == Result.moreau_jean_nonfinite and info.value.step == 6


def test_the_differentiable_trajectory_raises_the_members_message():
    model = Blowup(m=1.0, k=1.0)
    with pytest.raises(Exception, match="non-finite value .NaN or inf. appeared in the smooth motion"):
        jax.block_until_ready(nj.integrate(model, nj.DS(), 0.0, 0.1, 0.01, jnp.ones(1), jnp.zeros(1)).ts)
    traj = nj.integrate(model, nj.DS(), 0.0, 0.1, 0.01, jnp.ones(1), jnp.zeros(1), throw=False)
    assert bool(traj.failed)
    assert Result(int(traj.records.result[6])) == Result.smooth_nonfinite  # step 6 (row 0: the initial state)


def test_iteration_plots_name_each_schemes_subproblems(ball_runs, tmp_path):
    from nsga_jax import _plotting as plotting
    from nsga_jax._output import plot_iterations

    titles = {"ds": ["smooth motion", "position correction", "velocity jump"],
              "cs": ["coupled (CS) iteration"], "mj": ["Moreau–Jean (velocity-level)"]}
    for scheme, sol in ball_runs.items():
        with plotting.capture() as figures:
            plot_iterations(sol, tmp_path / f"{scheme}.png", "bouncing_ball", scheme=scheme)
        (fig,) = figures.values()
        axes = [ax for ax in fig.axes if ax.get_visible()]
        assert [ax.get_title(loc="left").split(":")[0] for ax in axes] == titles[scheme]
        for i, ax in enumerate(axes):
            (stairs,) = ax.patches
            np.testing.assert_array_equal(stairs.get_data().values, sol.iterations[1:, i])
