"""float32 runs, and strided records for long runs (statistics over every step)."""

import json

import numpy as np
import pytest

import nsga_jax as nj
from nsga_jax.chunks import load_chunks
from nsga_jax.cli import main
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


def test_cli_record_every_keeps_every_step_on_disk(tmp_path):
    out = tmp_path / "ball"
    assert main(["run", "bouncing_ball", "--h", "1e-2", "--t-end", "2", "--record-every", "10",
                 "--chunk", "64", "--out", str(out), "--quiet"]) == 0
    data = np.load(out / "trajectory.npz")
    assert data["t"].shape == (21,)
    steps = load_chunks(out, "steps")
    assert steps["t"].shape == (200,)
    np.testing.assert_array_equal(steps["q"][9::10], data["q"][1:])
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


def test_precision_switch_does_not_leak_constants():
    # JAX caches the NumPy constants a traced function closes over without their precision;
    # precision() clears the caches around float32 code, so each precision sees its own.
    import jax
    import jax.numpy as jnp

    from nsga_jax._simulate import precision

    C = np.linspace(0.0, 1.0, 24).reshape(8, 3)

    def f(x):
        return jnp.sum(C * x)

    with precision("float32"):
        assert jax.jit(f)(np.ones(3)).dtype == np.float32
    assert jax.jit(f)(np.ones(3)).dtype == np.float64
    with precision("float32"):
        assert jax.jit(f)(np.ones(3)).dtype == np.float32


def test_float32_failure_message_names_the_precision():
    scene = load_scene("rigid_pendulum", {"scheme": "cs", "max_iter": 1, "dtype": "float32"})
    with pytest.raises(nj.ConvergenceError, match=r"coupled \(CS\) iteration.*in float32 .* rerun in float64"):
        scene.run()
