"""The memory estimate (nsga_jax/_memory.py): calibrated against the peaks
recorded in docs/performance.md, and a model that cannot fit refused before
anything is compiled, from Python and from the command line."""

from __future__ import annotations

import re

import numpy as np
import pytest
from reference_models import BouncingBall

import nsga_jax as nj
from nsga_jax import _memory as memory
from nsga_jax._cli import EXIT_INPUT, main
from nsga_jax._sweep import sweep
from nsga_jax.scenes import load_scene

RECORDED = {3: (192, 0.65), 5: (648, 0.70), 7: (1536, 0.86), 9: (3000, 1.40), 11: (5184, 2.84)}
"""divisions: (coordinates, peak resident memory [GB]) of the flexible cube,
20 steps of DS at h = 1e-4 s with every sub-problem active
(``experiments/tools/memory_peak.py``; the table of docs/performance.md)."""

BALL = BouncingBall(m=1.0, gravity=9.81, e=0.5)
CUBE_40_DENSE = r"\d,\d{3} GB estimated for 206,763 coordinates .*21.3 GB available; use a smaller model"
CUBE_40_RECORDS = (r"keeping the records of 10,000 steps needs \d+\.\d GB .* beside \d\.\d GB of matrices, 21.3 GB "
                   r"available; keep every k-th step")
"""Moreau-Jean on the 40-division cube takes the matrix-free path (8 GB): its records refuse it."""
DENSE = nj.DS(krylov_min_dof=None)
"""DS on its dense path (a large cube is otherwise solved without assembling: test_krylov.py)."""


@pytest.fixture(scope="module")
def cube_40():
    """The flexible cube at its largest mesh with Moreau–Jean (model only:
    nothing is compiled)."""
    return load_scene("flexible_cube", {"divisions": 40, "scheme": "mj"})


@pytest.fixture
def machine_of(monkeypatch):
    """Set the available memory [bytes] the check sees (and clear the skip variable)."""
    monkeypatch.delenv(memory.SKIP_ENV, raising=False)

    def set_available(n_bytes):
        monkeypatch.setattr(memory, "available_memory", lambda: n_bytes)

    return set_available


@pytest.mark.parametrize("divisions", sorted(RECORDED))
def test_estimate_is_within_a_factor_of_1_5_of_the_recorded_peaks(divisions):
    n, peak = RECORDED[divisions]
    model = load_scene("flexible_cube", {"divisions": divisions}).model
    est = memory.estimate_run_bytes(model, DENSE, 8)
    assert model.n_dof == n
    assert 1 / 1.5 < est.total / (peak * 1e9) < 1.5


def test_dense_count_follows_the_kinds_of_the_iteration_matrices():
    cube = load_scene("flexible_cube", {"divisions": 3}).model  # nonlinear force, constant mass, 192 >= 100 dofs
    # DS: M, three held LU factors in and out of a chunk, and a refactor's K, A and LU
    assert memory.dense_matrices(cube, nj.DS()) == 1 + 2 * 3 + 3
    assert memory.dense_matrices(cube, nj.DS(reuse_min_dof=10**6)) == 1 + 3  # refactored: nothing held
    assert memory.dense_matrices(cube, nj.MJ()) == 1 + 3
    bar = load_scene("impacting_bar", {"n_elements": 20}).model  # linear, constant mass: inverted once
    assert memory.dense_matrices(bar, nj.DS()) >= 3  # M, K, C and the inverses (or blocks) of the constant matrices
    # bytes: n² per matrix, per member, per byte of the precision
    one, four = (memory.estimate_run_bytes(cube, nj.DS(), 4, members=m).dense_bytes for m in (1, 4))
    assert four == 4 * one
    assert memory.estimate_run_bytes(cube, nj.DS(), 8).dense_bytes == 2 * one


def test_cube_at_40_divisions_is_refused_from_python_before_compiling(cube_40, machine_of, no_compilation):
    machine_of(21.3e9)
    with pytest.raises(nj.ConfigError, match="^flexible_cube: .*" + CUBE_40_RECORDS):
        cube_40.run()  # matrix-free: its matrices fit, its records of every step do not (named by the scene)
    for dense in (DENSE, nj.MJ(krylov_min_dof=None)):
        with pytest.raises(nj.ConfigError, match=CUBE_40_DENSE):
            nj.simulate(cube_40.model, dense, 0.0, 0.01, 1e-4, cube_40.q0, cube_40.v0)


def test_cube_at_40_divisions_is_refused_by_the_command_line_in_one_line(tmp_path, capsys, machine_of):
    machine_of(21.3e9)
    code = main(["run", "flexible_cube", "--set", "divisions=40", "--scheme", "mj", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == EXIT_INPUT
    assert err[-1].startswith("error: ") and "Traceback" not in "\n".join(err)
    assert re.search("flexible_cube: .*" + CUBE_40_RECORDS, err[-1])
    assert not (tmp_path / "o").exists()  # refused before a folder is claimed


def test_a_small_model_passes_on_this_machine():
    cube = load_scene("flexible_cube", {"divisions": 5}).model
    est = memory.check_fits(cube, nj.DS(), 8)
    assert est.n_dof == 648 and est.needed < 1e9
    available = memory.available_memory()
    assert available is None or available > est.needed


def test_skipping_the_check_goes_on_to_compile(cube_40, machine_of, monkeypatch, no_compilation):
    machine_of(1e6)  # 1 MB: the cube at 40 divisions is refused ...
    with pytest.raises(nj.ConfigError):
        cube_40.run()
    # ... but not when asked to skip: the run goes on to compile (forbidden here)
    with pytest.raises(AssertionError, match="compilation started"):
        cube_40.run(check_memory=False, first_step_limit=None)  # MJ's dense first step: hours (test_first_step.py)
    monkeypatch.setenv(memory.SKIP_ENV, "1")
    with pytest.raises(AssertionError, match="compilation started"):
        cube_40.run(first_step_limit=None)


def test_unknown_available_memory_refuses_nothing(cube_40, machine_of):
    machine_of(None)
    assert memory.check_fits(cube_40.model, DENSE, 8).dense_bytes > 1e12


def test_available_memory_is_read_where_the_platform_says(monkeypatch):
    available = memory.available_memory()
    assert available is None or available > 0

    def no_file(*args, **kwargs):
        raise OSError("no /proc")

    monkeypatch.setattr("builtins.open", no_file)  # no /proc/meminfo: the available pages, or unknown
    fallback = memory.available_memory()
    assert fallback is None or fallback > 0


def test_batch_sweep_and_integrate_are_refused_before_compiling(machine_of):
    machine_of(10)  # 10 bytes: not even the ball's 1 x 1 matrices fit
    with pytest.raises(nj.ConfigError, match=r"the batch: .* for each of 2 runs"):
        nj.simulate_batch(BALL, nj.DS(), 0.0, 1.0, [1e-2, 2e-2], [1.0], [0.0])
    with pytest.raises(nj.ConfigError, match=r"a batch of bouncing_ball: "):
        sweep("bouncing_ball", {"e": [0.2, 0.5]})
    with pytest.raises(nj.ConfigError, match=r"the model: .* GB estimated for 1 coordinates"):
        nj.integrate(BALL, nj.DS(), 0.0, 1.0, 1e-2, np.array([1.0]), np.array([0.0]))


# ------------------------------------------------- the first minute of a large run


def test_a_large_model_runs_in_short_chunks_so_its_progress_shows_within_a_minute(cube_40):
    """The 40-division cube passes the memory check on the matrix-free path
    (about 8 GB) and steps at about 1.8 s: chunks of 64 steps, the old
    floor, showed nothing for two minutes; chunks of 4 show each 7 s."""
    from types import SimpleNamespace

    from nsga_jax._simulate import chunk_length

    assert chunk_length(cube_40.model) == 4
    assert chunk_length(SimpleNamespace(n_dof=648)) == 128  # the paper's cube, as before
    assert chunk_length(SimpleNamespace(n_dof=1)) == 4096  # a ball, as before


def test_progress_says_it_compiles_then_the_time_a_step_and_the_time_left(capsys, monkeypatch):
    from nsga_jax import _progress as progress

    clock = iter([0.0, 0.0, 26.0, 26.0, 38.0, 38.0])  # created, compiling, compiled (twice), chunk 1 (twice)
    monkeypatch.setattr(progress.time, "perf_counter", lambda: next(clock))
    shown = progress.Progress(n_steps=10_000, t0=0.0, h=3e-5, enabled=True)
    shown.compiled(shown.compiling(206_763), "compiled")
    shown.chunk(4, last=False)
    err = capsys.readouterr().err
    assert "compiling the step (206,763 coordinates) ... 26.0 s\n" in err
    assert "step 4/10000 (  0.0 %), t = 0.00012 s, 3 s a step, 8.33 h left" in err
    assert [progress.duration(s) for s in (12.0, 210.0, 18_000.0)] == ["12 s", "3.5 min", "5 h"]
