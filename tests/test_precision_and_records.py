"""float32 runs, and strided records for long runs (statistics over every step)."""

import json
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest
from reference_models import BouncingBall

import nsga_jax as nj
from nsga_jax._chunks import load_chunks
from nsga_jax._cli import main
from nsga_jax.scenes import load_scene

# ------------------------------------------------------------ strided records


def test_strided_records_keep_every_kth_step_and_full_statistics():
    scene = load_scene("bouncing_ball", {"t_end": 3.0})
    full = scene.run()
    strided = scene.run(saveat=nj.SaveAt(every=7), chunk_size=100)
    assert strided.n_steps == full.n_steps == 3000
    kept = np.r_[np.arange(0, 3001, 7), 3000]  # every 7th step, the initial state and the last step
    np.testing.assert_array_equal(strided.ts, full.ts[kept])
    np.testing.assert_array_equal(strided.q, full.q[kept])
    np.testing.assert_array_equal(strided.observables["energy"], full.observables["energy"][kept])
    for key in ("iterations", "failed_steps", "max_penetration", "n_steps"):
        assert strided.stats[key] == full.stats[key]


def test_strided_records_keep_every_failure():
    scene = load_scene("rigid_pendulum", {"max_iter": 1, "t_end": 2.0})
    full = scene.run(throw=False)
    strided = scene.run(throw=False, saveat=nj.SaveAt(every=10))
    assert len(full.failed_steps) >= 2
    np.testing.assert_array_equal(strided.failed_steps, full.failed_steps)
    assert strided.stats["iterations"] == full.stats["iterations"]
    with pytest.raises(nj.ConvergenceError) as info:
        scene.run(saveat=nj.SaveAt(every=10))
    sol = info.value.solution
    assert sol.n_steps == info.value.step and sol.ts[-1] == pytest.approx(info.value.time)


def test_cli_record_every_keeps_the_kept_steps_only(tmp_path):
    out = tmp_path / "ball"
    assert main(["run", "bouncing_ball", "--h", "1e-2", "--t-end", "2", "--record-every", "10",
                 "--chunk", "64", "--out", str(out), "--quiet"]) == 0
    data = np.load(out / "trajectory.npz")
    assert data["t"].shape == (21,)
    assert not (out / "partial").exists() and not (out / "steps").exists()  # trajectory.npz holds them all
    assert load_chunks(out) == {}
    assert json.loads((out / "summary.json").read_text())["n_steps"] == 200


# ---------------------------------------------------------------- float32


@pytest.mark.parametrize("name, overrides", [("bouncing_ball", {"t_end": 1.0}),
                                             ("impacting_bar", {"t_end": 0.6, "n_elements": 50}),
                                             ("rigid_pendulum", {"t_end": 0.8})])
def test_float32_run_converges_and_follows_float64(name, overrides, tol=1e-4):
    scene = load_scene(name, overrides)
    ref = scene.run()
    sol = scene.run(dtype="float32")
    np.testing.assert_array_equal(scene.run().q, ref.q)  # float64 after float32: unchanged
    assert sol.q.dtype == np.float32 and sol.records.impulse.dtype == np.float32
    assert sol.stats["failed_steps"] == 0
    scale = np.abs(ref.q).max()
    assert np.abs(sol.q - ref.q).max() < tol * scale
    assert sol.observables["energy"].dtype == np.float64  # observables are evaluated in float64


def test_float32_with_friction_is_warned_by_name():
    """A sticking contact creeps in float32 (the position correction accepts a
    slip of the gaps' round-off a step: three boxes at rest move 0.6 mm in
    1 s, docs/accuracy.md): a float32 run of a frictional model is warned
    (``PrecisionWarning``) before it runs, by simulate and by integrate when
    it is traced, and the warning is kept in the run's warnings; a
    frictionless or float64 run is not."""
    import jax

    from nsga_jax._precision import cast_floats, precision_notes

    stack = load_scene("box_stack", {"dim": 2, "n_boxes": 2, "t_end": 0.002})
    with pytest.warns(nj.PrecisionWarning, match="float32 with Coulomb friction: a sticking contact may creep"):
        sol = stack.run(dtype="float32")
    assert any(w.startswith("float32 with Coulomb friction") for w in sol.stats["warnings"])
    model, scheme = cast_floats((stack.model, stack.scheme()), "float32")
    with pytest.warns(nj.PrecisionWarning, match="float32 with Coulomb friction"):
        jax.eval_shape(lambda q, v: nj.integrate(model, scheme, 0.0, 0.002, 1e-3, q, v, n_steps=2),
                       np.asarray(stack.q0, np.float32), np.asarray(stack.v0, np.float32))
    frictionless = load_scene("box_stack", {"dim": 2, "n_boxes": 2, "mu": 0.0})
    with warnings.catch_warnings():
        warnings.simplefilter("error", nj.PrecisionWarning)
        assert precision_notes(stack.model, "float64") == precision_notes(frictionless.model, "float32") == []


def test_integrate_refuses_float32_states_with_a_float64_model_by_name():
    """integrate takes the model and scheme as given: float32 q0 and v0 with
    float64 parameters would mix precisions inside the loop (a raw TypeError
    of the scan); refused before tracing, naming the parameter and the cast."""
    from nsga_jax import cast_floats

    ball = load_scene("bouncing_ball")
    q0, v0 = np.asarray(ball.q0, np.float32), np.asarray(ball.v0, np.float32)
    with pytest.raises(nj.ConfigError, match=r"q0 and v0 are float32 but the model's parameter model\.\w+.* "
                                             r"is float64: cast both with nsga_jax\.cast_floats"):
        nj.integrate(ball.model, ball.scheme(), 0.0, 0.01, 1e-3, q0, v0)
    model = cast_floats(ball.model, "float32")
    with pytest.raises(nj.ConfigError, match=r"the scheme's parameter scheme\.\w+"):
        nj.integrate(model, ball.scheme(), 0.0, 0.01, 1e-3, q0, v0)
    model, scheme = cast_floats((ball.model, ball.scheme()), "float32")
    sol = nj.integrate(model, scheme, 0.0, 0.01, 1e-3, q0, v0)
    assert sol.q.dtype == np.float32


def _float64_values(jaxpr) -> list[str]:
    """The equations of ``jaxpr`` (and of the jaxprs nested in it) that make a
    float64 value, and its float64 constants; weakly typed values (Python
    numbers) take the precision of what they meet and are not counted."""
    import jax.extend as jex

    found = [f"constant {v.aval}" for v in jaxpr.constvars if v.aval.dtype == np.float64]
    for eqn in jaxpr.eqns:
        if any(getattr(v.aval, "dtype", None) == np.float64 and not v.aval.weak_type for v in eqn.outvars):
            found.append(f"{eqn.primitive.name} at {eqn.source_info.traceback}")
        for param in eqn.params.values():
            for sub in param if isinstance(param, (list, tuple)) else (param,):
                if isinstance(sub, jex.core.ClosedJaxpr):
                    found += _float64_values(sub.jaxpr)
                elif isinstance(sub, jex.core.Jaxpr):
                    found += _float64_values(sub)
    return found


@pytest.mark.parametrize("name", ["impacting_bar", "rigid_box", "flexible_pendulum", "flexible_cube"])
def test_float32_run_computes_in_float32_with_x64_on(name):
    # the precision comes from the inputs: with x64 on, the float32 programs of
    # simulate (preparation and initial state, and the chunk of steps) hold no float64 value
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from nsga_jax import cast_floats
    from nsga_jax._run_core import prepare_and_init, run_chunk

    assert jax.config.jax_enable_x64
    scene = load_scene(name)
    model, scheme = cast_floats((scene.model, scene.scheme()), "float32")
    t0, h = jnp.float32(0.0), jnp.float32(scene.solver["h"])
    q0, v0 = jnp.asarray(scene.q0, jnp.float32), jnp.asarray(scene.v0, jnp.float32)
    prepare = eqx.filter_make_jaxpr(prepare_and_init)(model, scheme, t0, q0, v0, h)[0]
    assert _float64_values(prepare.jaxpr) == []
    ops, state = prepare_and_init(model, scheme, t0, q0, v0, h)
    assert state.q.dtype == state.t.dtype == state.a.dtype == jnp.float32
    chunk = eqx.filter_make_jaxpr(lambda *args: run_chunk(*args, 2))(
        model, scheme, ops, state, h, t0, jnp.asarray(2, jnp.int32), jnp.asarray(False))[0]
    assert _float64_values(chunk.jaxpr) == []


def test_float64_run_refused_with_x64_off():
    import jax

    scene = load_scene("bouncing_ball", {"t_end": 0.01})
    with jax.enable_x64(False), pytest.raises(nj.ConfigError, match="jax_enable_x64"):
        scene.run(dtype="float64")


def test_float64_inputs_refused_by_integrate_with_x64_off():
    """integrate takes its precision from q0 and v0: float64 NumPy inputs
    with the 64-bit mode off would be rounded to float32 silently, so they
    are refused by name; float32 JAX arrays run in float32."""
    import jax
    import jax.numpy as jnp

    ball = BouncingBall(m=1.0, gravity=9.81, e=0.8)
    with jax.enable_x64(False):
        with pytest.raises(nj.ConfigError, match="q0 is float64 but JAX's 64-bit mode is off"):
            nj.integrate(ball, nj.DS(), 0.0, 0.01, 1e-3, np.array([1.0]), np.array([0.0]))
        with pytest.raises(nj.ConfigError, match='dtype="float64"'):
            nj.simulate_batch(ball, nj.DS(), 0.0, 0.01, [1e-3], [1.0], [0.0])
        sol = nj.integrate(ball, nj.DS(tol_r=1e-5), 0.0, 0.01, 1e-3, jnp.array([1.0]), jnp.array([0.0]))
    assert sol.q.dtype == jnp.float32 and int(sol.result) == 0


def test_float64_only_computations_refused_with_x64_off():
    """check_model (comparisons relative to 1e-8) and parametrize of a
    float64 scene (its parameters would be float32 arrays, and integrate
    would then run in float32 without a word) refuse by name while JAX's
    64-bit mode is off; a float32 scene is parametrized as float32."""
    import jax

    ball = BouncingBall(m=1.0, gravity=9.81, e=0.8)
    with jax.enable_x64(False):
        with pytest.raises(nj.ConfigError, match="check_model computes in float64 and needs JAX's 64-bit mode"):
            nj.check_model(ball, np.array([1.0]), np.array([0.0]))
        with pytest.raises(nj.ConfigError, match='dtype="float64" \\(the default\\) needs JAX'):
            nj.scenes.parametrize("impacting_bar", {"t_end": 0.01}, names=["E"])
        params, _ = nj.scenes.parametrize("impacting_bar", {"t_end": 0.01, "dtype": "float32"}, names=["E"])
        assert params["E"].dtype == np.float32
    assert nj.check_model(ball, np.array([1.0]), np.array([0.0]))[0] == "sizes"  # x64 on: it runs


def test_importing_nsga_jax_changes_no_global_state():
    """A fresh process: importing the package and its numerical modules, and
    building a scene, leaves JAX's 64-bit mode and XLA_FLAGS as they were;
    a float64 run is then refused by name, and runs once the caller turns
    the mode on."""
    code = (
        "import os, jax\n"
        "before = (jax.config.jax_enable_x64, os.environ.get('XLA_FLAGS'))\n"
        "import nsga_jax as nj, nsga_jax._simulate, nsga_jax._batch, nsga_jax.system, nsga_jax.scenes\n"
        "scene = nsga_jax.scenes.load_scene('bouncing_ball', {'t_end': 0.01})\n"
        "assert (jax.config.jax_enable_x64, os.environ.get('XLA_FLAGS')) == before == (False, None), before\n"
        "try:\n    scene.run()\nexcept nj.ConfigError as err:\n    print('refused:', err)\n"
        "jax.config.update('jax_enable_x64', True)\n"
        "scene = nsga_jax.scenes.load_scene('bouncing_ball', {'t_end': 0.01})\n"
        "print('ran', scene.run().q.dtype)\n")
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAX_ENABLE_X64")}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "refused: dtype=\"float64\" (the default) needs JAX's 64-bit mode" in out.stdout
    assert "ran float64" in out.stdout


@pytest.mark.parametrize("user_flags", [None, "--xla_cpu_enable_concurrency_optimized_scheduler=true"])
def test_configure_jax_sets_float64_and_the_cpu_flag_unless_the_user_chose(user_flags):
    """nsga_jax.configure_jax(), what the command line calls: JAX's 64-bit
    mode on (also when JAX loads after it) and the scheduler flag added to
    XLA_FLAGS, where the user's own value of the flag is kept."""
    code = ("import os, nsga_jax\n"
            "nsga_jax.configure_jax()\n"
            "import jax\n"
            "print(jax.config.jax_enable_x64, os.environ['XLA_FLAGS'])\n")
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAX_ENABLE_X64")}
    if user_flags is not None:
        env["XLA_FLAGS"] = user_flags
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    expected = user_flags or "--xla_cpu_enable_concurrency_optimized_scheduler=false"
    assert out.stdout.split() == ["True", expected]


def test_runs_of_either_precision_do_not_leak_into_each_other():
    """float64, float32, float64 in one process: each run computes in its own
    precision (JAX caches the constants a traced function closes over, so a
    program traced for one precision must never serve the other), and the
    second float64 run equals the first exactly."""
    scene = load_scene("bouncing_ball", {"t_end": 0.4})
    first = scene.run(dtype="float64")
    single = scene.run(dtype="float32")
    again = scene.run(dtype="float64")
    assert first.q.dtype == again.q.dtype == np.float64 and single.q.dtype == np.float32
    np.testing.assert_array_equal(first.q, again.q)
    np.testing.assert_array_equal(first.v, again.v)
    np.testing.assert_allclose(single.q, first.q, rtol=0, atol=1e-4)


def test_float32_failure_message_names_the_precision():
    scene = load_scene("rigid_pendulum", {"scheme": "cs", "max_iter": 1, "dtype": "float32"})
    with pytest.raises(nj.ConvergenceError, match=r"coupled \(CS\) iteration.*in float32 .* rerun in float64"):
        scene.run()
