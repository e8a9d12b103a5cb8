"""Fast paths agree with the generic path; another h or parameter value reuses
the compilation; the benchmark writes its table. (Speed itself is measured by
``nsga-jax bench``, not asserted here.)"""

import csv
import dataclasses

import jax
import numpy as np
import pytest

from nsga_jax import simulate
from nsga_jax._bench import COLUMNS, _batched, _bench_scene, bench
from nsga_jax._compilation_cache import compilation_cache
from nsga_jax._integrators.linalg import band_product
from nsga_jax._integrators.records import output_template
from nsga_jax._results import ConfigError
from nsga_jax.scenes import load_scene

WINDOWS = {
    "bouncing_ball": {"t_end": 1.0},
    "rigid_pendulum": {"t_end": 1.0},
    "impacting_bar": {"t_end": 0.7},
    "rigid_box": {"t_end": 0.3},
    "flexible_pendulum": {"t_end": 0.03},
}
CUBE = {"h": 3e-5, "t_end": 0.0006, "height": 0.0505, "velocity": -2.43}


def fast_against_generic(name, overrides, scheme="ds", atol=1e-9, **settings):
    scene = load_scene(name, {**overrides, "scheme": scheme})
    fast = dataclasses.replace(scene.scheme(), **settings)
    generic = dataclasses.replace(fast, fast_paths=False)
    args = (0.0, scene.solver["t_end"], scene.solver["h"], scene.q0, scene.v0)
    a = simulate(scene.model, fast, *args)
    b = simulate(scene.model, generic, *args)
    assert a.n_steps == b.n_steps
    for x, y in ((a.q, b.q), (a.v, b.v)):
        np.testing.assert_allclose(x, y, rtol=0, atol=atol * (np.abs(y).max() + 1e-12))
    np.testing.assert_array_equal(a.records.active_velocity, b.records.active_velocity)


@pytest.mark.parametrize("name", sorted(WINDOWS))
def test_fast_paths_agree_with_generic_path(name):
    fast_against_generic(name, WINDOWS[name])


@pytest.mark.parametrize("scheme", ["cs", "mj"])
def test_fast_paths_agree_for_other_schemes(scheme):
    fast_against_generic("impacting_bar", WINDOWS["impacting_bar"], scheme)


@pytest.mark.slow
def test_fast_paths_agree_on_the_cube():
    """The cube's fast path keeps its factorisations between iterations and
    steps (modified Newton), so its iterates differ from Newton's: compared at
    a tight tolerance, where both converged solutions are close to exact."""
    fast_against_generic("flexible_cube", CUBE, atol=1e-8, tol_r=1e-10, tol_f=1e-10)


def test_generic_path_keeps_nothing_constant():
    scene = load_scene("impacting_bar")
    generic = dataclasses.replace(scene.scheme(), fast_paths=False)
    ops = generic.prepare(scene.model, 1e-3, 0.0)
    assert not any(getattr(ops, f.name).is_constant for f in dataclasses.fields(ops))
    ops = scene.scheme().prepare(scene.model, 1e-3, 0.0)
    assert ops.smooth.is_constant and ops.position.is_constant and ops.velocity.is_constant
    # the 201-node bar's M and K are tridiagonal: its products with them are done on the band
    M, K = ops.mass.M, ops.force.K
    assert scene.model.bandwidth == 1 and ops.mass.band.shape == ops.force.K_band.shape == (3, 201)
    x = np.random.default_rng(0).normal(size=201)
    np.testing.assert_allclose(band_product(ops.mass.band, x), M @ x, rtol=1e-13, atol=1e-13 * np.abs(M).max())
    np.testing.assert_allclose(band_product(ops.force.K_band, x), K @ x, rtol=0, atol=1e-13 * np.abs(K @ x).max())


def test_no_recompilation_when_only_h_or_parameters_change():
    """Later runs with another h, E, e, v0 or step count compile none of the
    simulation's programs: every backend compile they trigger is far shorter
    than the first run's (scene building and observables may compile tiny
    eager ops for new shapes, in milliseconds; the bar's chunk program takes
    seconds). Measured against the first run, not a fixed bound, so that a
    loaded machine slows both alike."""
    compiles = []

    def listen(event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            compiles.append(duration)

    # the first run compiles its programs, whatever ran before in this process (no persistent cache either)
    jax.clear_caches()
    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        with compilation_cache(None):
            load_scene("impacting_bar", {"t_end": 0.2}).run()
            first_compile = max(compiles)
            compiles.clear()
            for overrides in ({"h": 1.3e-3}, {"E": 700.0, "e": 0.5, "velocity": 8.0}, {"h": 7e-4, "t_end": 0.3}):
                load_scene("impacting_bar", {"t_end": 0.2, **overrides}).run()
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    assert max(compiles, default=0.0) < 0.1 * first_compile, (first_compile, sorted(compiles)[-3:])


def test_bench_writes_its_table(tmp_path):
    rows = bench(["bouncing_ball"], [1, 8], ["float64", "float32"], repeats=1, max_steps=200, out=tmp_path,
                 progress=False)
    with open(tmp_path / "bench.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert len(rows) == len(table) == 4
    assert set(COLUMNS) <= set(table[0])
    for r in rows:
        assert r["us_per_step"] > 0 and r["compile_s"] > 0 and r["compile_cached_s"] > 0 and r["steps"] == 200
        assert r["member_steps_per_s"] == pytest.approx(r["batch"] * 1e6 / r["us_per_step"])
    f32 = [r for r in rows if r["dtype"] == "float32"]
    assert all(0 < r["float32_error"] < 1e-4 for r in f32)
    assert {(r["dtype"], r["batch"]) for r in rows} == {("float64", 1), ("float64", 8), ("float32", 1),
                                                       ("float32", 8)}


def test_a_batch_is_skipped_on_its_probes_estimate():
    """A batch whose first steps say a run would exceed max_seconds is not run
    in full (its estimate is returned instead of its timings)."""
    scene = _bench_scene("bouncing_ball", {"scheme": "ds"}, 400)
    estimate, timing = _batched(scene, "float64", 8, 1, max_seconds=1e-9)
    assert timing is None and estimate > 0
    estimate, (compile_s, wall, cached) = _batched(scene, "float64", 8, 1, max_seconds=1e9)
    assert compile_s > 0 and wall > 0 and cached > 0


@pytest.mark.parametrize("scheme", ["ds", "dsn", "cs", "mj"])
@pytest.mark.parametrize("name", ["bouncing_ball", "rigid_pendulum", "rigid_box"])
def test_record_template_matches_the_step(name, scheme):
    """The time loops size their record buffers from the model's sizes; the
    step must return exactly those shapes and dtypes."""
    scene = load_scene(name, {"scheme": scheme})
    model, sch = scene.model, scene.scheme()
    ops = sch.prepare(model, 1e-3, 0.0)
    state = sch.init(model, 0.0, scene.q0, scene.v0)
    traced = jax.eval_shape(lambda s: sch.step(model, ops, s, 1e-3)[1], state)
    assert traced == output_template(model, state.q.dtype, sch.subproblems)


@pytest.mark.parametrize("settings, message", [
    ({"repeats": 0}, "repeats must be an integer >= 1"),
    ({"max_steps": 0}, "max_steps must be an integer >= 1"),
    ({"max_seconds": -1.0}, r"max_seconds must be in \(0, inf\)"),
    ({"batches": [0]}, "batch sizes must be integers >= 1"),
    ({"dtypes": ["float16"]}, "dtype must be"),
])
def test_bad_bench_settings_are_refused_by_name(settings, message):
    with pytest.raises(ConfigError, match=message):
        bench(["bouncing_ball"], **{"batches": [1], "dtypes": ["float64"], **settings}, progress=False)


def test_device_check_agreement_runs(tmp_path):
    """experiments/tools/device_check.py, the check prepared for a GPU machine, runs
    as written; here its default device is the CPU, so the two sides agree
    exactly."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "experiments" / "tools" / "device_check.py"
    spec = importlib.util.spec_from_file_location("device_check", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    rows = module.agreement(tmp_path)
    assert [r["case"] for r in rows] == ["sweep bouncing_ball", "sweep impacting_bar", "flexible_pendulum q"]
    assert all(r["max_rel_difference"] == 0.0 for r in rows)
    assert (tmp_path / "agreement.csv").exists()
