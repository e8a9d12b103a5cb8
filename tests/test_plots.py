"""Plots: every axis labelled with a unit (or what it counts), every figure
titled with its scene, scheme and h, sweeps drawn one line per group, Newton
iterations as integers, readable default selections, and no matplotlib
backend chosen at import."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import nsga_jax
from nsga_jax import _plotting as plotting
from nsga_jax._identify import Data, Identification, write_identification
from nsga_jax._output import plot_iterations, plot_observables, summary, write_run
from nsga_jax._studies import Reference, StudyRow, write_study
from nsga_jax._sweep import SweepResult, plot_sweep
from nsga_jax.scenes import REGISTRY

COUNTS = ("iteration", "solves", "steps")


def has_unit(text: str) -> bool:
    return bool(re.search(r"\[[^\]]+\]", text)) or any(w in text for w in COUNTS)


def visible_axes(fig):
    return [ax for ax in fig.axes if ax.get_visible()]


def check_figure(fig, *words):
    """Labels with units on both axes of every panel (an x label may be on the
    panel below, for shared x axes), a title holding ``words``, and no text
    that overlaps other text (tick labels, the title, legends)."""
    with plotting.style():  # tick positions depend on the style's font sizes
        _check_figure(fig, words)


def _check_figure(fig, words):
    renderer = fig.canvas.get_renderer()
    for ax in visible_axes(fig):
        assert has_unit(ax.get_ylabel()), ax.get_ylabel()
        xlabels = [a.get_xlabel() for a in ax.get_shared_x_axes().get_siblings(ax) if a.get_visible()]
        assert any(has_unit(t) for t in xlabels), xlabels
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            boxes = [t.get_window_extent(renderer) for loc, t in zip(axis.get_majorticklocs(),
                                                                   axis.get_majorticklabels())
                     if t.get_text() and lo - 1e-12 * abs(hi - lo) <= loc <= hi + 1e-12 * abs(hi - lo)]
            for a, b in zip(boxes, boxes[1:]):
                assert not a.padded(2.0).overlaps(b), [t.get_text() for t in axis.get_majorticklabels()]
    heading = fig.get_suptitle()
    for w in words:
        assert w in heading, (w, heading)
    top = fig._suptitle.get_window_extent(renderer)
    for artist in visible_axes(fig) + fig.legends:
        assert not top.overlaps(artist.get_tightbbox(renderer)), heading


# ------------------------------------------------------------------ runs


def fake_solution(names, n=666, t_end=666 * 3e-5, failed=()):
    """What the run plots read from a :class:`~nsga_jax.Solution`."""
    ts = np.linspace(0.0, t_end, n + 1)
    rng = np.random.default_rng(0)
    iterations = rng.integers(0, 4, size=(n + 1, 3))
    iterations[0] = 0
    return SimpleNamespace(ts=ts, h=t_end / n, n_steps=n, iterations=iterations,
                           failed_steps=np.asarray(failed, dtype=int),
                           observables={k: np.sin(ts * (i + 1)) for i, k in enumerate(names)})


@pytest.fixture(scope="module")
def ball_run():
    scene = nsga_jax.load_scene("bouncing_ball", {"t_end": 0.5, "h": 2e-3})
    return scene, scene.run(progress=False)


def test_run_plots_have_units_titles_and_integer_iterations(ball_run, tmp_path):
    scene, sol = ball_run
    with plotting.capture() as figures:
        paths = write_run(sol, tmp_path, summary(sol, scene.name, "ds"))
    assert set(figures) == {paths["observables_plot"], paths["iterations_plot"]}
    obs = figures[paths["observables_plot"]]
    check_figure(obs, "bouncing_ball", "DS", "h = 0.002 s")
    assert [ax.get_ylabel() for ax in visible_axes(obs)] == ["z [m]", "vz [m/s]", "force [N]", "energy [J]"]

    it = figures[paths["iterations_plot"]]
    check_figure(it, "bouncing_ball", "DS", "h = 0.002 s")
    axes = visible_axes(it)
    assert len(axes) == 3  # smooth motion, position correction, velocity jump
    for i, ax in enumerate(axes):
        (stairs,) = ax.patches
        np.testing.assert_array_equal(stairs.get_data().values, sol.iterations[1:, i])  # no offsets
        ticks = ax.get_yticks()
        np.testing.assert_array_equal(ticks, np.round(ticks))


def test_failed_steps_are_marked(tmp_path):
    sol = fake_solution(["z"], failed=[50, 51])
    with plotting.capture() as figures:
        plot_iterations(sol, tmp_path / "i.png", "bouncing_ball", scheme="cs")
        plot_observables(sol, tmp_path / "o.png", "bouncing_ball", scheme="cs")
    it, obs = figures.values()
    for ax in visible_axes(it):
        (crosses,) = [line for line in ax.lines if line.get_label() == "failed step"]
        np.testing.assert_allclose(crosses.get_xdata(), [50 * sol.h, 51 * sol.h])
    assert "2 failed steps" in obs.get_suptitle()
    for ax in visible_axes(obs):
        (line,) = [line for line in ax.lines if line.get_label() == "first failed step"]
        assert line.get_xdata()[0] == pytest.approx(50 * sol.h)


@pytest.mark.parametrize("name", ["rigid_box", "flexible_cube", "flexible_pendulum"])
def test_many_observables_default_to_a_readable_selection(name, tmp_path):
    spec = REGISTRY[name]
    sol = fake_solution(spec.observables)
    with plotting.capture() as figures:
        plot_observables(sol, tmp_path / "a.png", name, scheme="ds")
        plot_observables(sol, tmp_path / "b.png", name, scheme="ds", names=["energy"])
    default, chosen = figures.values()
    check_figure(default, name, "DS")
    assert 4 <= len(visible_axes(default)) <= 9
    assert [ax.get_ylabel() for ax in visible_axes(chosen)] == ["energy [J]"]
    with pytest.raises(nsga_jax.ConfigError, match="nope"):
        plot_observables(sol, tmp_path / "c.png", name, names=["nope"])


def test_every_scene_observable_has_a_unit():
    for name, spec in REGISTRY.items():
        assert set(spec.units) == set(spec.observables), name
        assert set(spec.plotted) <= set(spec.observables), name
        assert len(spec.plotted or spec.observables) <= 9, name


def test_importing_nsga_jax_leaves_matplotlib_alone(tmp_path):
    code = f"""
import sys
import nsga_jax, nsga_jax._cli, nsga_jax._output, nsga_jax._studies, nsga_jax._sweep
import nsga_jax._identify, nsga_jax._plotting
assert not any(m.startswith("matplotlib") for m in sys.modules), "matplotlib imported"
import matplotlib
backend = matplotlib.rcParams._get("backend")
from tests.test_plots import fake_solution
nsga_jax._output.plot_observables(fake_solution(["z"]), {str(tmp_path / "o.png")!r}, "bouncing_ball")
assert "matplotlib.pyplot" not in sys.modules
assert matplotlib.rcParams._get("backend") == backend
"""
    root = Path(nsga_jax.__file__).parents[1]
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(root), "MPLBACKEND": "svg"})
    assert out.returncode == 0, out.stderr[-2000:]
    assert (tmp_path / "o.png").stat().st_size > 1000


# ----------------------------------------------------------------- studies


def study_rows():
    """DS, DSn and CS with identical errors (they often are), one CS failure."""
    rows = []
    for scheme in ("ds", "dsn", "cs"):
        for h in (1e-2, 5e-3, 2e-3, 1e-3):
            fails = scheme == "cs" and h == 1e-2
            err = {"z": np.nan, "vz": np.nan} if fails else {"z": 1.2 * h, "vz": 2.0 * h}
            rows.append(StudyRow(scheme=scheme, h=h, n_steps=int(1 / h), wall_time_s=1e-4 / h,
                                 compile_time_s=1.0, failed_steps=3 if fails else 0,
                                 first_failure_t=0.5 if fails else np.nan, result="successful",
                                 iterations={"linear_solves": {"mean": 3.0 if scheme == "cs" else 1.02,
                                                               "max": 9 if fails else 3}},
                                 errors=err))
    return rows


def test_study_plots_keep_identical_schemes_apart(tmp_path):
    with plotting.capture() as figures:
        paths = write_study(study_rows(), tmp_path, "bouncing_ball", Reference("exact solution"))
    for key in ("convergence", "iterations", "work_precision"):
        check_figure(figures[paths[key]], "bouncing_ball", "DS, DSN, CS", "h = 0.001 ... 0.01 s")
    conv = figures[paths["convergence"]]
    for ax in visible_axes(conv):
        curves = [line for line in ax.lines if line.get_label()[:2] in ("DS", "CS") and "failed" not in
                  line.get_label()]
        looks = {(line.get_marker(), line.get_linestyle(), line.get_markersize()) for line in curves}
        assert len(curves) == len(looks) == 3
        (failed,) = [line for line in ax.lines if line.get_label() == "CS failed"]
        assert list(failed.get_xdata()) == [1e-2]
        assert [t.get_text() for t in ax.get_xticklabels()] == ["0.001", "0.002", "0.005", "0.01"]
    its = figures[paths["iterations"]]
    ticks = visible_axes(its)[1].get_yticks()
    np.testing.assert_array_equal(ticks, np.round(ticks))


# ------------------------------------------------------------------ sweeps


def sweep_result(grid: dict[str, list[float]], failed_index=None) -> SweepResult:
    rows = []
    keys = list(grid)
    for i, combo in enumerate(np.stack(np.meshgrid(*grid.values(), indexing="ij"), -1).reshape(-1, len(keys))):
        values = dict(zip(keys, map(float, combo)))
        rows.append({"member": i, **values, "n_steps": 100, "result": "successful",
                     "failed_steps": int(i == failed_index), "solves_per_step_mean": 1.0 + values["h"],
                     "solves_per_step_max": 3, "max_penetration": 1e-9 * i, "z_final": 0.1 * i,
                     "vz_final": -0.2 * i, "error_z": values["h"] * (1 + i), "error_vz": values["h"]})
    return SweepResult(rows=rows, swept=keys)


def group_lines(ax):
    return [line for line in ax.lines if line.get_gid() == "group"]


def test_sweep_draws_one_line_per_step_size(tmp_path):
    result = sweep_result({"e": [0.5, 0.7, 0.9], "h": [1e-3, 2e-3]}, failed_index=2)
    (tmp_path / "sweep.json").write_text(json.dumps({"scene": "bouncing_ball", "overrides": {"scheme": "dsn"}}))
    with plotting.capture() as figures:
        plot_sweep(result, tmp_path / "sweep.png")  # scene and scheme from sweep.json
    (fig,) = figures.values()
    check_figure(fig, "bouncing_ball", "DSN", "h = 0.001 ... 0.002 s")
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert labels == ["h = 0.001 s", "h = 0.002 s", "failed run"]
    for ax in visible_axes(fig):
        assert ax.get_xlabel() == "e [-]"
        lines = group_lines(ax)
        assert len(lines) == 2
        for line in lines:
            assert list(line.get_xdata()) == [0.5, 0.7, 0.9]  # never joins two step sizes
    assert "max penetration [m]" in [ax.get_ylabel() for ax in visible_axes(fig)]


def test_sweep_picks_an_axis_that_keeps_groups_few(tmp_path):
    result = sweep_result({"e": [0.5, 0.9], "velocity": list(np.linspace(0, 1, 12)), "h": [1e-3, 2e-3]})
    with plotting.capture() as figures:
        plot_sweep(result, tmp_path / "sweep.png", scene="bouncing_ball", scheme="ds")
    (fig,) = figures.values()
    check_figure(fig, "bouncing_ball", "DS")
    for ax in visible_axes(fig):
        assert ax.get_xlabel() == "velocity [m/s]"
        assert len(group_lines(ax)) == 4  # (e, h) pairs

    many = sweep_result({"e": list(np.linspace(0.1, 0.9, 9)), "velocity": list(np.linspace(0, 1, 9)),
                         "h": [1e-3]})
    with plotting.capture() as figures:
        plot_sweep(many, tmp_path / "many.png", scene="bouncing_ball", scheme="ds")
    (fig,) = figures.values()
    check_figure(fig, "markers only")
    for ax in visible_axes(fig):
        (points,) = group_lines(ax)
        assert points.get_linestyle() == "None"


# ---------------------------------------------------------- identification


def test_identification_plots(tmp_path):
    t = np.linspace(0.0, 1.0, 51)
    data = Data(t=t, values={"z": 1 - t**2, "vz": -2 * t})
    result = Identification(names=["e"], initial={"e": 0.6}, recovered={"e": 0.8}, true={"e": 0.8},
                            losses=[0.1, 0.01, 1e-4, 1e-8], iterations=3, evaluations=5, stop="gradient",
                            wall_time_s=1.0, compile_time_s=1.0, fitted=dict(data.values),
                            initial_fit={k: 0.9 * v for k, v in data.values.items()})
    scene = nsga_jax.load_scene("bouncing_ball", {"h": 2e-3})
    with plotting.capture() as figures:
        paths = write_identification(result, data, tmp_path, scene=scene)
    for key in ("loss", "fit"):
        check_figure(figures[paths[key]], "bouncing_ball", "DS", "h = 0.002 s", "identification of e")
    assert [ax.get_ylabel() for ax in visible_axes(figures[paths["fit"]])] == ["z [m]", "vz [m/s]"]
    ticks = visible_axes(figures[paths["loss"]])[0].get_xticks()
    np.testing.assert_array_equal(ticks, np.round(ticks))
