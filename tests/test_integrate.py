"""The pure entry point ``integrate`` and the host driver ``simulate`` give one
``Solution``: the same arrays to round-off, under jit, grad and vmap; output
control by ``SaveAt``; named errors for what each cannot honour."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from reference_models import BouncingBall

import nsga_jax as nj
from nsga_jax._chunks import load_chunks
from nsga_jax.scenes import load_scene, parametrize

BALL = BouncingBall(m=1.0, gravity=9.81, e=0.8)
STAT_KEYS = ("failed_steps", "max_penetration", "max_bilateral_violation_position",
             "max_bilateral_violation_velocity")


def assert_same_run(pure, host, atol=1e-10):
    assert isinstance(pure, nj.Solution) and isinstance(host, nj.Solution)
    for name in ("ts", "q", "v", "impulse", "gap", "iterations"):
        np.testing.assert_allclose(np.asarray(getattr(pure, name)), getattr(host, name), rtol=0, atol=atol,
                                   err_msg=name)
    assert int(pure.result) == int(host.result)
    for key in STAT_KEYS:
        assert float(pure.stats[key]) == pytest.approx(host.stats[key], abs=atol), key
    for name, it in host.stats["iterations"].items():
        assert float(pure.stats["iterations"][name]["mean"]) == pytest.approx(it["mean"], rel=1e-12), name
        assert int(pure.stats["iterations"][name]["max"]) == it["max"], name


@pytest.mark.parametrize("name, overrides", [("bouncing_ball", {"t_end": 0.6}),
                                             ("impacting_bar", {"n_elements": 20, "t_end": 0.6, "h": 2e-3})])
def test_integrate_under_jit_equals_simulate(name, overrides):
    scene = load_scene(name, overrides)
    host = scene.run()
    t1, h = scene.solver["t_end"], scene.solver["h"]
    pure = jax.jit(lambda q0, v0: nj.integrate(scene.model, scene.scheme(), 0.0, t1, h, q0, v0))(scene.q0, scene.v0)
    assert pure.n_steps == host.n_steps and not bool(pure.failed) and not host.failed
    assert_same_run(pure, host)


def test_integrate_with_traced_h_and_n_steps_equals_simulate():
    host = nj.simulate(BALL, nj.DS(), 0.0, 0.5, 1e-3, [0.2], [0.0])  # an impact at t = 0.2 s
    pure = jax.jit(lambda h: nj.integrate(BALL, nj.DS(), 0.0, 500 * h, h, 0.2 * jnp.ones(1), jnp.zeros(1),
                                          n_steps=500))(1e-3)
    assert_same_run(pure, host)


def test_integrate_under_vmap_equals_simulate_per_member():
    heights = jnp.asarray([0.2, 0.1])
    batch = jax.jit(jax.vmap(lambda z: nj.integrate(BALL, nj.DS(), 0.0, 0.5, 1e-3, z[None], jnp.zeros(1))))(heights)
    assert batch.q.shape == (2, 501, 1)
    for i, z in enumerate(heights):
        host = nj.simulate(BALL, nj.DS(), 0.0, 0.5, 1e-3, [float(z)], [0.0])
        member = jax.tree_util.tree_map(lambda x, i=i: x[i], batch)
        assert_same_run(member, host)


def test_every_driver_reports_a_failing_run_with_the_same_fields():
    """One run core: a run whose position correction fails on some steps
    (an iteration cap of 1), kept going, gives the same trajectory, result,
    failure count, per-step result codes and statistics from the three
    drivers (the batch's single member, integrate under jit)."""
    scene = load_scene("rigid_pendulum", {"max_iter": 1, "t_end": 2.0})
    t1, h = scene.solver["t_end"], scene.solver["h"]
    host = scene.run(throw=False)
    member = nj.simulate_batch(scene.model, scene.scheme(), 0.0, t1, [h], scene.q0, scene.v0)[0]
    pure = jax.jit(lambda q0, v0: nj.integrate(scene.model, scene.scheme(), 0.0, t1, h, q0, v0, throw=False))(
        scene.q0, scene.v0)
    assert host.stats["failed_steps"] > 0 and host.result == nj.Result.position_max_iter
    for sol in (member, pure):
        assert_same_run(sol, host)
        assert nj.Result(int(sol.result)) is host.result
        np.testing.assert_array_equal(np.asarray(sol.records.result), host.records.result)
        assert sol.n_steps == host.n_steps == sol.n_steps_requested
    np.testing.assert_array_equal(member.failed_steps, host.failed_steps)
    np.testing.assert_array_equal(np.nonzero(np.asarray(pure.records.result))[0], host.failed_steps)


def test_saveat_every_equals_slicing_the_full_run():
    run = jax.jit(lambda saveat: nj.integrate(BALL, nj.DS(), 0.0, 0.5, 1e-3, 0.2 * jnp.ones(1), jnp.zeros(1),
                                              saveat=saveat), static_argnums=0)
    full, strided = run(nj.SaveAt()), run(nj.SaveAt(every=7))
    kept = np.r_[np.arange(0, 501, 7), 500]  # every 7th step, the initial state and the last step
    np.testing.assert_array_equal(strided.ts, full.ts[kept])
    for a, b in zip(jax.tree_util.tree_leaves(strided.records), jax.tree_util.tree_leaves(full.records)):
        np.testing.assert_array_equal(a, b[kept])
    for key in STAT_KEYS:
        assert float(strided.stats[key]) == float(full.stats[key])
    host = nj.simulate(BALL, nj.DS(), 0.0, 0.5, 1e-3, [0.2], [0.0], saveat=nj.SaveAt(every=7))
    np.testing.assert_allclose(strided.ts, host.ts, rtol=0, atol=1e-14)
    np.testing.assert_allclose(strided.q, host.q, rtol=0, atol=1e-12)


def test_saveat_fn_keeps_what_a_loss_needs_under_grad():
    """``jax.grad`` through ``integrate`` (a Solution as auxiliary output):
    keeping one number per step gives the full record's loss and gradient."""
    params, build = parametrize("bouncing_ball", {"h": 1e-3, "height": 0.2, "t_end": 0.5}, ["e", "height"])

    def loss(p, saveat):
        model, q0, v0, _ = build(p)
        sol = nj.integrate(model, nj.DS(), 0.0, 0.5, 1e-3, q0, v0, saveat=saveat)
        z = sol.q[:, 0] if saveat.fn is None else sol.records
        return jnp.mean(z**2), sol

    grad = jax.jit(jax.value_and_grad(loss, has_aux=True), static_argnums=1)
    (full, sol_full), g_full = grad(params, nj.SaveAt())
    (saved, sol_saved), g_saved = grad(params, nj.SaveAt(fn=lambda state, record: state.q[0]))
    assert isinstance(sol_full, nj.Solution) and sol_full.q.shape == (501, 1)
    assert sol_saved.q.shape == (0, 1) and sol_saved.records.shape == (501,)
    assert float(sol_full.stats["iterations"]["velocity"]["max"]) >= 1  # the impact is in the run
    assert float(saved) == pytest.approx(float(full), rel=1e-14)
    for k in params:
        assert float(g_full[k]) != 0.0
        np.testing.assert_allclose(float(g_saved[k]), float(g_full[k]), rtol=1e-12, err_msg=k)


def test_traced_times_need_n_steps():
    with pytest.raises(nj.ConfigError, match=r"n_steps must be given when t1 is traced"):
        jax.jit(lambda t1: nj.integrate(BALL, nj.DS(), 0.0, t1, 1e-3, jnp.ones(1), jnp.zeros(1)))(1.0)
    with pytest.raises(nj.ConfigError, match=r"n_steps must be given when t1, h are traced"):
        jax.grad(lambda h: nj.integrate(BALL, nj.DS(), 0.0, 10 * h, h, jnp.ones(1), jnp.zeros(1)).q.sum())(1e-3)
    with pytest.raises(nj.ConfigError, match=r"n_steps = 50 disagrees with floor\(\(t1 - t0\)/h\) = 100"):
        nj.integrate(BALL, nj.DS(), 0.0, 0.1, 1e-3, jnp.ones(1), jnp.zeros(1), n_steps=50)


@pytest.mark.parametrize("kwargs, error, match", [
    ({"every": 0}, nj.ConfigError, r"record_every must be an integer >= 1, got 0 \(SaveAt.every"),
    ({"every": True}, nj.ConfigError, r"record_every must be an integer >= 1, got bool True \(SaveAt.every"),
    ({"every": 2.5}, nj.ConfigError, r"record_every must be an integer >= 1, got float 2.5"),
    ({"fn": 3}, TypeError, r"SaveAt.fn must be a function \(state, record\) -> pytree or None, got int 3"),
    ({"chunks": 3}, TypeError, r"SaveAt.chunks must be a folder \(str or pathlib.Path\) or None, got int 3"),
])
def test_saveat_fields_are_checked(kwargs, error, match):
    with pytest.raises(error, match=match):
        nj.SaveAt(**kwargs)


def test_each_entry_point_refuses_what_only_the_other_honours(tmp_path):
    with pytest.raises(nj.ConfigError, match=r"integrate \(pure\) cannot honour SaveAt.chunks .*nsga_jax.simulate"):
        nj.integrate(BALL, nj.DS(), 0.0, 0.1, 1e-3, jnp.ones(1), jnp.zeros(1), saveat=nj.SaveAt(chunks=tmp_path))
    with pytest.raises(nj.ConfigError, match=r"simulate \(host driver\) cannot honour SaveAt.fn .*nsga_jax.integrate"):
        nj.simulate(BALL, nj.DS(), 0.0, 0.1, 1e-3, [1.0], [0.0], saveat=nj.SaveAt(fn=lambda s, r: s.q))
    with pytest.raises(TypeError, match=r"saveat must be a nsga_jax.SaveAt, got int 7"):
        nj.integrate(BALL, nj.DS(), 0.0, 0.1, 1e-3, jnp.ones(1), jnp.zeros(1), saveat=7)


def test_saveat_chunks_writes_the_kept_steps_to_disk_in_few_files(tmp_path):
    seen = []
    sol = nj.simulate(BALL, nj.DS(), 0.0, 0.5, 1e-3, [1.0], [0.0], chunk_size=64,
                      saveat=nj.SaveAt(every=10, chunks=tmp_path / "kept"),
                      on_chunk=lambda k, r: seen.append(len(r.t)))
    kept = load_chunks(tmp_path / "kept", ".")
    assert kept["t"].shape == (50,) and sol.ts.shape == (51,)
    assert len(list((tmp_path / "kept").glob("*.npz"))) == 1  # 8 chunks, gathered into one file
    assert seen == [64] * 7 + [52]  # the callback still sees every step of every chunk
    np.testing.assert_array_equal(kept["q"], sol.q[1:])
    np.testing.assert_allclose(kept["t"], sol.ts[1:], rtol=1e-12)


def test_simulate_batch_returns_one_solution_per_step_size():
    sols = nj.simulate_batch(BALL, nj.DS(), 0.0, 1.0, [1e-3, 2e-3], [1.0], [0.0])
    assert [type(s) for s in sols] == [nj.Solution, nj.Solution]
    single = nj.simulate(BALL, nj.DS(), 0.0, 1.0, 2e-3, [1.0], [0.0])
    np.testing.assert_allclose(sols[1].q, single.q, rtol=0, atol=1e-12)
    assert sols[1].stats["iterations"] == single.stats["iterations"]


SHARDED = """
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
import nsga_jax as nj
from reference_models import BouncingBall
assert len(jax.devices()) == 2
ball = BouncingBall(m=1.0, gravity=9.81, e=0.8)
h0 = jnp.asarray([0.3, 0.5, 0.7, 0.9])
q0 = h0[:, None]  # the ball's one coordinate: its height [m]
v0 = jnp.zeros_like(q0)

def final_height(q0, v0):
    sol = nj.integrate(ball, nj.DS(), 0.0, 0.6, 1e-3, q0, v0)
    return sol.q[-1, -1], sol.stats["failed_steps"]

run = jax.jit(jax.vmap(final_height))
mesh = Mesh(np.array(jax.devices()), ("members",))
spread = NamedSharding(mesh, P("members"))
sharded = run(jax.device_put(q0, spread), jax.device_put(v0, spread))
assert len(sharded[0].sharding.device_set) == 2, sharded[0].sharding
single = [final_height(q0[i], v0[i]) for i in range(4)]
np.testing.assert_allclose(np.asarray(sharded[0]), [float(s[0]) for s in single], rtol=0, atol=1e-12)
assert int(np.sum(sharded[1])) == 0
print("ok", np.asarray(sharded[0]).tolist())
"""


def test_integrate_with_members_sharded_over_two_devices():
    """The pure entry point under vmap with the members split over two CPU
    devices (a separate process: the device count is fixed at start-up)
    equals member-by-member runs."""
    import os
    import subprocess
    import sys
    import textwrap
    from pathlib import Path

    tests = str(Path(__file__).parent)  # where reference_models lives
    path = os.pathsep.join(p for p in (tests, os.environ.get("PYTHONPATH")) if p)
    env = {**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=2", "PYTHONPATH": path}
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(SHARDED)], env=env, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.startswith("ok")


@pytest.mark.parametrize("transform", ["grad", "jit", "vmap"])
@pytest.mark.parametrize("driver", ["simulate", "simulate_batch"])
def test_host_drivers_under_a_transformation_name_integrate(transform, driver):
    """simulate and simulate_batch run their loops on the host: traced inputs are
    refused before anything compiles, with a TypeError that names integrate."""
    def final_height(z0):
        q0 = jnp.reshape(z0, (1,))
        if driver == "simulate":
            return nj.simulate(BALL, nj.DS(), 0.0, 0.01, 1e-3, q0, [0.0]).q[-1, 0]
        return nj.simulate_batch(BALL, nj.DS(), 0.0, 0.01, [1e-3], q0, [0.0])[0].q[-1, 0]

    apply = {"grad": jax.grad, "jit": jax.jit, "vmap": jax.vmap}[transform]
    z0 = jnp.asarray([1.0, 2.0]) if transform == "vmap" else jnp.asarray(1.0)
    with pytest.raises(TypeError, match=f"nsga_jax.{driver} is a host driver .* nsga_jax.integrate takes the same"):
        apply(final_height)(z0)


def test_an_adjoint_named_by_a_string_is_refused_with_the_instances():
    with pytest.raises(TypeError, match=r"nsga_jax.DiscreteAdjoint\(\) or nsga_jax.ImpactTimeAdjoint\(\), got str"):
        nj.integrate(BALL, nj.DS(), 0.0, 0.01, 1e-3, [1.0], [0.0], adjoint="discrete")
