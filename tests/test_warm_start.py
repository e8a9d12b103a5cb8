"""Newton started from the last step's multipliers (``DS(warm_start=True)``,
a config's ``newton_start = "previous"``): the paper's zero start stays the
default; a warm-started run is the same motion to the Newton tolerance in
fewer iterations, with every scheme option, batch and adjoint it meets."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import nsga_jax as nj
from nsga_jax._integrators.contact_rows import multiplier_count
from nsga_jax.scenes import load_scene

H = 1e-3
pytestmark = pytest.mark.filterwarnings("ignore:impacts in sequence")  # the pushed box's landings (the scene's)


def stack(boxes=3, push=2.0, t_end=0.3, **solver):
    """The planar box stack, its top box pushed at ``push`` m/s: friction at
    every contact, the pushed box sliding over the one below, then falling."""
    return load_scene("box_stack", {"dim": 2, "n_boxes": boxes, "push": push, "t_end": t_end, "h": H, **solver})


def both(scene, scheme=nj.DS, **options):
    return [nj.simulate(scene.model, scheme(warm_start=warm, **options), 0.0, scene.solver["t_end"], H, scene.q0,
                        scene.v0) for warm in (False, True)]


def test_the_paper_start_is_the_default():
    scene = stack()
    assert nj.DS().init(scene.model, 0.0, scene.q0, scene.v0).multipliers is None
    start = nj.DS(warm_start=True).init(scene.model, 0.0, scene.q0, scene.v0).multipliers
    assert [m.shape for m in start] == [(multiplier_count(scene.model),)] * 2 and not any(map(jnp.any, start))
    assert scene.scheme() == nj.DS(rho_inf=scene.solver["rho_inf"])
    warm = stack(newton_start="previous")
    assert warm.scheme().warm_start
    with pytest.raises(nj.ConfigError, match="newton_start = 'previous' is an option of the schemes ds, dsn"):
        stack(newton_start="previous", scheme="mj")
    with pytest.raises(nj.ConfigError, match="newton_start"):
        stack(newton_start="last")
    with pytest.raises(nj.ConfigError, match="warm_start must be True or False"):
        nj.simulate(scene.model, nj.DS(warm_start=1), 0.0, 0.01, H, scene.q0, scene.v0)


def test_a_pushed_stack_is_the_same_motion_in_fewer_iterations():
    cold, warm = both(stack())
    for sol in (cold, warm):
        assert sol.stats["result"] == "successful" and sol.stats["failed_steps"] == 0
    np.testing.assert_allclose(warm.q, cold.q, atol=1e-5)  # both converged to eq. 51's tolerance
    for sub in ("position", "velocity"):  # 2.57 -> 1.34 and 2.24 -> 1.23 on average
        assert warm.stats["iterations"][sub]["mean"] < 0.7 * cold.stats["iterations"][sub]["mean"]
    assert abs(warm.q[-1, -3] - cold.q[-1, -3]) < 1e-6  # the top box's x at the end


def test_a_sub_problem_that_fails_hands_zero_to_the_next_step():
    """The next step starts from the multipliers a sub-problem converged to,
    and from zero (the paper's start) after one that did not converge. The
    top box pushed: the first step's position correction needs 3 iterations
    (at rest it needs one since Newton's matrix closes contacts at
    σ = ±round-off, so a cap of 1 no longer fails there)."""
    scene = stack(boxes=3, push=2.0)
    q0, v0 = jnp.asarray(scene.q0), jnp.asarray(scene.v0)
    for max_iter, converges in ((50, True), (1, False)):  # the first step's correction needs several iterations
        scheme = nj.DS(warm_start=True, max_iter=max_iter)

        @eqx.filter_jit
        def first_step(scheme, model, q0, v0):
            ops = scheme.prepare(model, jnp.asarray(H), jnp.asarray(0.0))
            return scheme.step(model, ops, scheme.init(model, 0.0, q0, v0), jnp.asarray(H))

        new, out = first_step(scheme, scene.model, q0, v0)
        position = new.multipliers[0]
        assert (int(out.result) == int(nj.Result.successful)) == converges
        assert bool(jnp.any(position != 0)) == converges  # the stack's weight and push, or zero after the failure


@pytest.mark.slow
@pytest.mark.parametrize("options", [dict(scheme=nj.DSn), dict(impact_instants=True)], ids=["DSn", "instants"])
def test_with_the_other_scheme_options(options):
    options = dict(options)  # the parametrized dict is shared: never change it
    scheme = options.pop("scheme", nj.DS)
    cold, warm = both(stack(boxes=2, t_end=0.2), scheme, **options)
    for sol in (cold, warm):
        assert sol.stats["result"] == "successful" and sol.stats["failed_steps"] == 0
        if options.get("impact_instants"):  # the top box's landing is located: the split steps carry the start
            assert sol.stats["impacts_at_instants"] >= 1
    np.testing.assert_allclose(warm.q, cold.q, atol=1e-5)
    assert warm.stats["iterations"]["position"]["mean"] <= cold.stats["iterations"]["position"]["mean"]


@pytest.mark.slow
def test_a_batch_carries_each_members_multipliers():
    scene = stack(boxes=2, t_end=0.1)
    hs = [1e-3, 2e-3]
    batch = nj.simulate_batch(scene.model, nj.DS(warm_start=True), 0.0, 0.1, hs, scene.q0, scene.v0)
    for h, member in zip(hs, batch):
        single = nj.simulate(scene.model, nj.DS(warm_start=True), 0.0, 0.1, h, scene.q0, scene.v0)
        np.testing.assert_allclose(member.q, single.q, atol=1e-10)


@pytest.mark.slow
@pytest.mark.parametrize("adjoint", [nj.DiscreteAdjoint(), nj.ImpactTimeAdjoint()], ids=["discrete", "impact-time"])
def test_gradients_equal_the_cold_starts(adjoint):
    """Newton's implicit derivative is taken at the converged multipliers,
    whatever the start: at tight Newton tolerances (both starts converge to
    the same multipliers) the gradients agree to round-off. A box pushed
    along the floor, both bottom corners sliding (it sticks at t = 0.041 s,
    where the law's kink lets the two runs end on different branches)."""
    scene = stack(boxes=1, t_end=0.03)
    steps = 30
    tight = dict(tol_r=1e-10, tol_f=1e-10)

    def loss(scheme, push):
        v0 = jnp.asarray(scene.v0).at[0].set(push)
        sol = nj.integrate(scene.model, scheme, 0.0, steps * H, H, scene.q0, v0, n_steps=steps, adjoint=adjoint)
        return sol.q[-1, 0] + sol.v[-1, 0]  # the box's x and its speed

    cold = jax.value_and_grad(lambda p: loss(nj.DS(**tight), p))(0.2)
    warm = jax.value_and_grad(lambda p: loss(nj.DS(**tight, warm_start=True), p))(0.2)
    assert abs(float(cold[1])) > 1e-3
    np.testing.assert_allclose(warm, cold, rtol=1e-8)
