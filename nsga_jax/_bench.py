"""Benchmarks: ``nsga-jax bench`` and :func:`bench`.

For each scene, precision and batch size, the time per step of complete runs
(compile time apart, minimum over repeats), the batched throughput (member
steps per second), the compile time (cold, and loaded from the persistent
cache by a later run), the linear solves per step, the cost of
one dense LU factorisation and solve of the scene's n × n matrix (the unit of
a nonlinear model's Newton iteration), and for float32 the eq. 52 distance of
its first error observable from the float64 run. Rows go to ``DIR/bench.csv``
as they are measured, with the device they ran on; the same command runs on a
CPU or a GPU machine unchanged.
"""

from __future__ import annotations

import csv
import dataclasses
import os
import platform
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ._batch import BatchRun, broadcast_members
from ._compilation_cache import compilation_cache
from ._metrics import relative_l1_error
from ._precision import DTYPES, cast_floats
from ._results import ConfigError
from ._scenes import REGISTRY, Scene, load_scene
from ._validation import choice, integer, real, step_count

CASES: dict[str, dict] = {
    "bouncing_ball": {"h": 1e-3},
    "rigid_pendulum": {"h": 1e-3},
    "impacting_bar": {"h": 1e-3},
    "rigid_box": {"h": 1e-3},
    "flexible_pendulum": {"h": 1e-4},
    # the paper's cube at its smallest step, started just above the floor at its impact speed
    "flexible_cube": {"h": 1e-4, "t_end": 0.006, "height": 0.0505, "velocity": -2.43},
}
"""Each scene's benchmark configuration (overrides of its defaults)."""

COLUMNS = ("scene", "scheme", "h", "batch", "dtype", "device", "n_dof", "steps", "us_per_step",
           "member_steps_per_s", "speedup_vs_single", "compile_s", "compile_cached_s", "solves_per_step",
           "failed_steps",
           "factor_solve_us", "float32_error")


def device_name() -> str:
    d = jax.devices()[0]
    if d.platform == "cpu":
        return f"cpu ({platform.machine()}, {os.cpu_count()} cores)"
    return f"{d.platform} ({d.device_kind})"


def per_call(step: Callable, x0, repeats: int, inner: int) -> float:
    """Seconds per call of ``x -> step(x)``, chained ``inner`` times in one compiled
    loop (no dispatch overhead; each call depends on the previous one)."""
    loop = jax.jit(lambda x: jax.lax.fori_loop(0, inner, lambda i, x: step(x), x))
    jax.block_until_ready(loop(x0))
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(loop(x0))
        best = min(best, time.perf_counter() - t)
    return best / inner


def factor_solve_seconds(n: int, dtype: str, repeats: int = 3) -> float:
    """One dense LU factorisation and solve of an n × n system."""
    rng = np.random.default_rng(0)
    A = jnp.asarray(rng.normal(size=(n, n)) + n * np.eye(n), dtype)
    tiny = 1e-30
    inner = max(3, min(2000, int(2e6 / n**2)))
    return per_call(lambda x: jnp.linalg.solve(A + tiny * x[0], x), jnp.ones(n, dtype), repeats, inner)


def _bench_scene(name: str, overrides: dict, max_steps: int) -> Scene:
    scene = load_scene(name, {**CASES.get(name, {}), **overrides})
    h = scene.solver["h"]
    t_end = min(scene.solver["t_end"], max_steps * h)
    return load_scene(name, {**CASES.get(name, {}), **overrides, "t_end": t_end})


def _single(scene: Scene, dtype: str, repeats: int):
    """(first run, best wall time, compile time of a later run loading the
    programs from the persistent cache)."""
    runs = [scene.run(dtype=dtype, throw=False) for _ in range(repeats)]
    best = min(r.wall_time for r in runs)
    jax.clear_caches()  # a later process: nothing compiled in memory
    shortest = dataclasses.replace(scene, solver={**scene.solver, "t_end": scene.solver["h"]})  # same programs
    return runs[0], best, shortest.run(dtype=dtype, throw=False).compile_time


PROBE_FRACTION = 20
PROBE_MIN_STEPS = 10
"""A batch's run time is estimated from a probe of its first 1/PROBE_FRACTION
steps (at least PROBE_MIN_STEPS: a first step can cost several later ones,
the cube's factoring every member's matrices) before it is measured in full."""


def _batched(scene: Scene, dtype: str, batch: int, repeats: int,
             max_seconds: float) -> tuple[float, tuple[float, float, float] | None]:
    """``(estimate, timing)`` of ``batch`` identical members: one run's time
    [s] estimated from a probe of its first steps, and (compile time, best
    wall time, compile time from the persistent cache), or ``None`` when the
    estimate exceeds ``max_seconds`` (the batch is then not run in full)."""
    n = step_count(0.0, scene.solver["t_end"], scene.solver["h"])
    model, scheme = cast_floats((scene.model, scene.scheme()), dtype)
    members = broadcast_members(model, batch)
    q0 = np.tile(scene.q0.astype(dtype), (batch, 1))
    v0 = np.tile(scene.v0.astype(dtype), (batch, 1))
    hs = np.full(batch, scene.solver["h"], dtype)

    def run(steps: int) -> tuple[BatchRun, float]:
        """The batch run for ``steps`` steps, and its preparation's wall time [s]."""
        out = BatchRun(members, scheme, 0.0, q0, v0, hs, np.full(batch, steps))
        prepared = out.wall_time
        for _ in out.chunks():
            pass
        return out, prepared

    probe_steps = min(n, max(PROBE_MIN_STEPS, n // PROBE_FRACTION))
    probe, prepared = run(probe_steps)  # the first, cold compilation: the same programs whatever the steps
    estimate = prepared + (probe.wall_time - prepared) * n / probe_steps
    if estimate > max_seconds:
        return estimate, None
    best = min(run(n)[0].wall_time for _ in range(repeats))
    jax.clear_caches()
    cached = BatchRun(members, scheme, 0.0, q0, v0, hs, np.full(batch, n)).compile_time
    return estimate, (probe.compile_time, best, cached)


def bench(
    scenes: Sequence[str] | None = None,
    batches: Sequence[int] = (1, 64, 1024),
    dtypes: Sequence[str] = ("float64", "float32"),
    *,
    scheme: str = "ds",
    repeats: int = 3,
    max_steps: int = 2000,
    max_seconds: float = 60.0,
    out: str | Path | None = None,
    progress: bool = True,
) -> list[dict]:
    """Measure every (scene, dtype, batch); see the module docstring.

    Compile times are measured with a persistent compilation cache in a fresh
    temporary folder (whatever cache the caller uses): ``compile_s`` is the
    first, cold compilation; ``compile_cached_s`` that of a later run of the
    same configuration, which loads the programs from the cache (what every
    run but the first costs with the command line's cache on).

    A batched configuration whose estimated run time exceeds ``max_seconds``
    is skipped and said so: first from the single run's speed (members ×
    steps × its time per step), then from a probe of the batch's own first
    steps (:data:`PROBE_FRACTION`), since a batch can be slower per member
    than single runs (the cube's).
    Each row is appended to ``out/bench.csv`` as soon as it is measured.
    """
    scenes = list(REGISTRY) if scenes is None else list(scenes)
    for s in scenes:
        if s not in REGISTRY:
            raise ConfigError(f"unknown scene {s!r}; built-in scenes: {', '.join(sorted(REGISTRY))}")
    for b in batches:
        try:
            integer("batch", b, 1)
        except ConfigError:
            raise ConfigError(f"batch sizes must be integers >= 1, got {b!r}") from None
    for d in dtypes:
        choice("dtype", d, DTYPES)
    for name, value in (("repeats", repeats), ("max_steps", max_steps)):
        integer(name, value, 1)
    real("max_seconds", max_seconds, 0.0, lo_open=True)
    path = None
    if out is not None:
        Path(out).mkdir(parents=True, exist_ok=True)
        path = Path(out) / "bench.csv"
        with open(path, "w", newline="") as f:
            csv.DictWriter(f, fieldnames=COLUMNS).writeheader()
    with tempfile.TemporaryDirectory(prefix="nsga_jax_bench_cache_") as cache, compilation_cache(cache):
        return _measure(scenes, batches, dtypes, scheme, repeats, max_steps, max_seconds, path, progress)


def _measure(scenes, batches, dtypes, scheme, repeats, max_steps, max_seconds, path, progress) -> list[dict]:
    device = device_name()
    rows = []
    for name in scenes:
        scene = _bench_scene(name, {"scheme": scheme}, max_steps)
        h = scene.solver["h"]
        reference = None
        for dtype in dtypes:
            single, wall, single_cached = _single(scene, dtype, repeats)
            steps = single.n_steps
            if single.stats["failed_steps"] and progress:
                print(f"{name} {dtype}: warning: {single.stats['failed_steps']} failed step(s) "
                      f"({single.result.name}); its timings are those of a failing run", flush=True)
            single_us = 1e6 * wall / steps
            error: float | str = ""  # float32's error against float64 ("" for float64 itself)
            observable = (scene.spec.error_observables or scene.spec.observables)[0]
            if dtype == "float64":
                reference = single
            elif reference is not None:
                error = relative_l1_error(single.observables[observable], reference.observables[observable])
            fs = 1e6 * factor_solve_seconds(scene.model.n_dof, dtype)
            common = {"scene": name, "scheme": scheme, "h": h, "dtype": dtype, "device": device,
                      "n_dof": scene.model.n_dof, "steps": steps,
                      "solves_per_step": single.stats["iterations"]["linear_solves"]["mean"],
                      "failed_steps": single.stats["failed_steps"],
                      "factor_solve_us": fs, "float32_error": error}
            for batch in batches:
                if batch == 1:
                    compile_s, us, cached = single.compile_time, single_us, single_cached
                else:
                    estimate, timing = batch * steps * single_us * 1e-6, None
                    how = "at the single run's speed"
                    if estimate <= max_seconds:
                        estimate, timing = _batched(scene, dtype, batch, repeats, max_seconds)
                        how = "from its first steps"
                    if timing is None:
                        if progress:
                            print(f"{name} {dtype} batch {batch}: skipped (about {estimate:.0f} s a run, {how}; "
                                  f"--max-seconds {max_seconds:g})", flush=True)
                        continue
                    compile_s, wall_b, cached = timing
                    us = 1e6 * wall_b / steps
                row = {**common, "batch": batch, "us_per_step": us, "member_steps_per_s": batch * 1e6 / us,
                       "speedup_vs_single": batch * single_us / us, "compile_s": compile_s,
                       "compile_cached_s": cached}
                rows.append(row)
                if path is not None:
                    with open(path, "a", newline="") as f:
                        csv.DictWriter(f, fieldnames=COLUMNS).writerow(row)
                if progress:
                    print(f"{name} {dtype} batch {batch}: {us:.1f} us/step, {row['member_steps_per_s']:.3g} "
                          f"member-steps/s ({row['speedup_vs_single']:.1f}x single), compile {compile_s:.1f} s "
                          f"({cached:.1f} s from the cache)",
                          flush=True)
    return rows


def markdown(rows: list[dict]) -> str:
    """The benchmark table of ``rows`` (Markdown, as docs/performance.md shows it)."""
    lines = ["| scene | n | h [s] | dtype | batch | µs/step | member-steps/s | × single | compile [s] "
             "| cached [s] | solves/step | dense factor+solve [µs] | float32 − float64 (eq. 52) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        err = r["float32_error"]
        err = f"{float(err):.1e}" if err not in ("", None) else ""
        lines.append(f"| {r['scene']} | {r['n_dof']} | {float(r['h']):g} | {r['dtype']} | {r['batch']} | "
                     f"{float(r['us_per_step']):.1f} | {float(r['member_steps_per_s']):.3g} | "
                     f"{float(r['speedup_vs_single']):.1f} | {float(r['compile_s']):.1f} | "
                     f"{_optional(r.get('compile_cached_s'), '.1f')} | "
                     f"{float(r['solves_per_step']):.2f} | {float(r['factor_solve_us']):.1f} | {err} |")
    return "\n".join(lines)


def _optional(value, fmt: str) -> str:
    """``value`` formatted, or empty where a table read from an older CSV lacks it."""
    return "" if value in ("", None) else format(float(value), fmt)
