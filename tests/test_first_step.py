"""The first step's time on the dense path (nsga_jax/_first_step.py): counted
from the kinds of the iteration matrices, refused before anything is
compiled when it is estimated above the limit, announced with the compiling
line when it is long, and run anyway when asked."""

from __future__ import annotations

import re
from types import SimpleNamespace

import pytest
from reference_models import BouncingBall

import nsga_jax as nj
from nsga_jax import _first_step as first_step
from nsga_jax import _memory as memory
from nsga_jax._chunks import chunk_plan
from nsga_jax._cli import EXIT_INPUT, main
from nsga_jax.scenes import load_scene

BALL = BouncingBall(m=1.0, gravity=9.81, e=0.5)
DENSE = nj.DS(krylov_min_dof=None)
"""DS on its dense path (a large matrix-free model is otherwise solved without assembling)."""
RATE = first_step.LU_RATE
"""A fixed LU rate [operations/s], so the figures below do not depend on this machine's load."""

STRUCTURE = ("n_bilateral", "n_constraints", "n_unilateral", "n_friction", "constant_mass", "linear_force",
             "linear_constraints", "velocity_dependent_force", "matrix_free", "bandwidth",
             "body_coupling")


@pytest.fixture(scope="module")
def small_cube():
    return load_scene("flexible_cube", {"divisions": 3})


def cube_of(small_cube, n_dof: int) -> SimpleNamespace:
    """The flexible cube's structure at ``n_dof`` coordinates, without building
    it (the estimate reads only n and the static structure)."""
    return SimpleNamespace(n_dof=n_dof, **{k: getattr(small_cube.model, k) for k in STRUCTURE})


def test_factorisations_follow_the_kinds_of_the_iteration_matrices(small_cube):
    cube = small_cube.model  # nonlinear force, constant mass, unilateral contacts
    count = first_step.first_step_factorisations
    # the generalized-α schemes solve with M for the initial acceleration (1), then
    assert count(cube, DENSE) == 1 + 1  # DS: the smooth motion's held LU (contacts iterate only when active)
    assert count(cube, nj.DS(reuse_min_dof=10**6, krylov_min_dof=None)) == 1 + 1  # refactored: one per iteration
    assert count(cube, nj.CS()) == 1 + 3  # a global iteration factorises all three
    assert count(cube, nj.MJ()) == 1  # no initial acceleration
    assert count(cube_of(small_cube, 206_763), nj.DS()) == 0  # matrix-free: nothing factorised
    assert count(BALL, nj.DS()) == 1 + 3 * first_step.INVERSE_LUS  # three constant matrices, each inverted once


@pytest.mark.parametrize("divisions, n_dof, scheme, pattern", [
    (40, 206_763, nj.MJ(krylov_min_dof=None),
     r"MJ on 206,763 coordinates is estimated at \d[\d.]* h for 1 LU factorisation of 206,763 x 206,763"),
    (15, 12_288, DENSE, r"DS on 12,288 coordinates is estimated at [\d.]+ min for 2 LU factorisations"),
    (15, 12_288, nj.CS(krylov_min_dof=None),
     r"CS on 12,288 coordinates is estimated at [\d.]+ min for 4 LU factorisations"),
])
def test_a_large_dense_cube_is_refused_naming_the_estimate(small_cube, divisions, n_dof, scheme, pattern):
    cube = cube_of(small_cube, n_dof)
    with pytest.raises(nj.ConfigError, match=pattern) as err:
        first_step.check_first_step(cube, scheme, rate=RATE, what="flexible_cube")
    message = str(err.value)
    assert message.startswith("flexible_cube: the first step of")
    assert "the limit is 60 s" in message and "first_step_limit=None (--first-step-limit inf)" in message
    assert "the matrix-free path, which every scheme takes for a matrix-free model this size" in message
    # the matrix-free path of the same model is not refused, whichever the scheme
    for matrix_free in (nj.DS(), nj.MJ(), nj.CS()):
        assert first_step.check_first_step(cube, matrix_free, rate=RATE).seconds == 0.0


def test_a_small_cube_is_not_refused_and_times_nothing(small_cube, monkeypatch):
    def no_probe(*args, **kwargs):
        raise AssertionError("a small model needs no measured rate")

    monkeypatch.setattr(first_step, "lu_rate", no_probe)
    cube = load_scene("flexible_cube", {"divisions": 5}).model
    for scheme in (DENSE, nj.CS(), nj.MJ()):
        assert first_step.check_first_step(cube, scheme).seconds < 0.1


def test_a_tiny_limit_refuses_before_compiling_and_none_runs_anyway(small_cube, no_compilation):
    refused = r"the first step of DS on 1 coordinates is estimated at .* limit is 1e-15"
    with pytest.raises(nj.ConfigError, match=refused):
        nj.simulate(BALL, nj.DS(), 0.0, 0.01, 1e-3, [1.0], [0.0], first_step_limit=1e-15)
    with pytest.raises(nj.ConfigError, match=r"first_step_limit must be a positive number of seconds, inf or None"):
        nj.simulate(BALL, nj.DS(), 0.0, 0.01, 1e-3, [1.0], [0.0], first_step_limit=-1.0)
    with pytest.raises(nj.ConfigError, match=r"^flexible_cube: the first step of DS on 192 coordinates"):
        small_cube.run(first_step_limit=1e-15)
    with pytest.raises(AssertionError, match="compilation started"):  # past every check
        small_cube.run(first_step_limit=None)


def test_the_override_lets_a_refused_run_proceed():
    with pytest.raises(nj.ConfigError):
        nj.simulate(BALL, nj.DS(), 0.0, 0.01, 1e-3, [1.0], [0.0], first_step_limit=1e-15)
    sol = nj.simulate(BALL, nj.DS(), 0.0, 0.01, 1e-3, [1.0], [0.0], first_step_limit=None)
    assert sol.n_steps == 10


def test_a_long_first_step_is_announced_and_run_alone_in_the_first_chunk(monkeypatch, capsys):
    import nsga_jax._simulate as simulate_module

    monkeypatch.setattr(simulate_module, "NOTE_SECONDS", 0.0)  # the ball's first step counts as long
    sizes = []
    nj.simulate(BALL, nj.DS(), 0.0, 0.01, 1e-3, [1.0], [0.0], chunk_size=4, progress=True,
                on_chunk=lambda k, records: sizes.append(len(records.t)))
    assert sizes == [1, 4, 4, 1]
    err = capsys.readouterr().err
    assert re.search(r"compiling the step \(1 coordinates; first step estimated at .* for 10 LU factorisations "
                     r"of 1 x 1\) \.\.\.", err)
    caps = iter([1, 100, 2, 100])
    assert list(chunk_plan(10, 4, cap=lambda: next(caps))) == [(1, 1), (2, 4), (6, 2), (8, 3)]
    assert list(chunk_plan(10, 4)) == [(1, 4), (5, 4), (9, 2)]


def test_a_slow_run_shows_progress_every_ten_seconds_or_so(monkeypatch):
    from nsga_jax import _progress as progress

    clock = iter([0.0, 0.0, 26.0, 59.0, 60.0])  # created, compiling, compiled, after the first step; another run
    monkeypatch.setattr(progress.time, "perf_counter", lambda: next(clock))
    shown = progress.Progress(n_steps=10_000, t0=0.0, h=3e-5, enabled=False)
    shown.compiled(shown.compiling(12_288, "2.75 min for 4 LU factorisations of 12,288 x 12,288"), "compiled")
    assert shown.next_chunk() == 1  # the long first step alone
    shown.chunk(1, last=False)
    assert shown.next_chunk() == 0  # 33 s a step: one a chunk (chunk_plan takes at least one)
    fast = progress.Progress(n_steps=10, t0=0.0, h=1.0, enabled=False)
    assert fast.next_chunk() >= 4096  # nothing measured, no long estimate: the chunk length decides


def test_the_command_line_refuses_in_one_line_and_runs_anyway_with_inf(tmp_path, capsys, monkeypatch, no_compilation):
    monkeypatch.setattr(memory, "available_memory", lambda: None)  # the memory check refuses nothing
    monkeypatch.setattr(first_step, "lu_rate", lambda *args: RATE)
    args = ["run", "flexible_cube", "--set", "divisions=3", "--scheme", "cs", "--out", str(tmp_path / "o")]
    code = main([*args, "--first-step-limit", "1e-12"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == EXIT_INPUT and "Traceback" not in "\n".join(err)
    assert re.match(r"error: flexible_cube: the first step of CS on 192 coordinates is estimated at", err[-1])
    with pytest.raises(AssertionError, match="compilation started"):
        main([*args, "--first-step-limit", "inf", "--overwrite"])


def test_a_batch_counts_its_members_and_is_refused_by_name_before_compiling(small_cube):
    cube = cube_of(small_cube, 12_288)
    one = first_step.estimate_first_step(cube, DENSE, rate=RATE)
    batch = first_step.estimate_first_step(cube, DENSE, rate=RATE, members=8)
    assert batch.factorisations == 8 * one.factorisations and batch.seconds == pytest.approx(8 * one.seconds)
    with pytest.raises(nj.ConfigError, match=r"^the batch: the first step of DS on 12,288 coordinates \(8 members "
                                             r"stepped together\) is estimated at .* use fewer members a batch"):
        first_step.check_first_step(cube, DENSE, rate=RATE, members=8, what="the batch")


def test_every_entry_point_refuses_a_long_first_step_before_compiling(tmp_path, monkeypatch):
    import jax

    from nsga_jax._sweep import sweep

    def nothing_compiles(*args, **kwargs):
        raise AssertionError("compilation started before the first-step check")

    monkeypatch.setattr(jax, "jit", nothing_compiles)
    refused = r"the first step of DS on 1 coordinates .* the limit is 1e-15 s"
    with pytest.raises(nj.ConfigError, match=r"^the batch: " + refused):
        nj.simulate_batch(BALL, nj.DS(), 0.0, 0.01, [1e-3, 2e-3], [1.0], [0.0], first_step_limit=1e-15)
    with pytest.raises(nj.ConfigError, match=r"^the model: " + refused):
        nj.integrate(BALL, nj.DS(), 0.0, 0.01, 1e-3, jax.numpy.ones(1), jax.numpy.zeros(1), first_step_limit=1e-15)
    with pytest.raises(nj.ConfigError, match=r"first_step_limit must be a positive number of seconds"):
        nj.integrate(BALL, nj.DS(), 0.0, 0.01, 1e-3, jax.numpy.ones(1), jax.numpy.zeros(1), first_step_limit=0.0)
    with pytest.raises(nj.ConfigError, match=r"^a batch of bouncing_ball: the first step of DS on 1 coordinates "
                                             r"\(4 members stepped together\)"):
        sweep("bouncing_ball", {"e": [0.5, 0.6, 0.7, 0.8]}, batch_size=4, first_step_limit=1e-15,
                 out=tmp_path / "sweep", devices=jax.devices()[:1])
    assert not (tmp_path / "sweep").exists()  # refused before the sweep claimed its folder


def test_the_sweep_command_refuses_in_one_line(tmp_path, capsys):
    code = main(["sweep", "bouncing_ball", "--grid", "e=0.5:0.6:2", "--first-step-limit", "1e-15", "--quiet",
                 "--out", str(tmp_path / "s")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == EXIT_INPUT and "Traceback" not in "\n".join(err)
    assert re.match(r"error: a batch of bouncing_ball: the first step of DS on 1 coordinates \(2 members", err[-1])
    assert not (tmp_path / "s").exists()  # a refused sweep leaves no empty folder
    (tmp_path / "deep").mkdir()
    assert main(["sweep", "bouncing_ball", "--grid", "e=0.5", "--first-step-limit", "1e-15", "--quiet",
                 "--out", str(tmp_path / "deep" / "er" / "s")]) == EXIT_INPUT
    assert list((tmp_path / "deep").iterdir()) == []  # nor the parents it created; one that existed stays
    assert main(["sweep", "bouncing_ball", "--grid", "e=0.5", "--first-step-limit", "1e-15", "--quiet",
                 "--out", str(tmp_path / "deep")]) == EXIT_INPUT
    assert (tmp_path / "deep").is_dir()  # a folder the user made is never deleted
    assert main(["sweep", "bouncing_ball", "--grid", "e=0.5", "--first-step-limit", "-1", "--quiet"]) == EXIT_INPUT
    assert "--first-step-limit must be a positive number of seconds" in capsys.readouterr().err


def test_studies_and_identification_take_the_limit(tmp_path, capsys, no_compilation):
    from nsga_jax._studies import make_reference, study

    reference = make_reference("bouncing_ball", {}, "exact")
    with pytest.raises(nj.ConfigError, match=r"^the batch: the first step of DS on 1 coordinates \(2 members"):
        study("bouncing_ball", ["ds"], [1e-3, 9e-4], reference, {"t_end": 0.01}, first_step_limit=1e-15)
    with pytest.raises(nj.ConfigError, match=r"^the model: the first step of DS on 1 coordinates"):
        study("bouncing_ball", ["ds"], [1e-3], reference, {"t_end": 0.01}, first_step_limit=1e-15)
    with pytest.raises(nj.ConfigError, match=r"^bouncing_ball: the first step of DS"):
        make_reference("bouncing_ball", {"t_end": 0.01}, 1e-4, first_step_limit=1e-15)
    with pytest.raises(TypeError, match=r"first_step_limit must be a number of seconds, inf or None, got str"):
        nj.simulate_batch(BALL, nj.DS(), 0.0, 0.01, [1e-3], [1.0], [0.0], first_step_limit="60")
    code = main(["convergence", "bouncing_ball", "--ref", "exact", "--h", "1e-3,9e-4", "--t-end", "0.01",
                 "--first-step-limit", "1e-15", "--out", str(tmp_path / "c")])
    assert code == EXIT_INPUT and re.search(r"error: the batch: the first step of DS", capsys.readouterr().err)
    assert not (tmp_path / "c").exists()  # a refused study leaves no empty folder
    assert main(["identify", "bouncing_ball", "--params", "e", "--synthetic", "--first-step-limit", "0"]) == EXIT_INPUT
    assert "--first-step-limit must be a positive number of seconds" in capsys.readouterr().err
