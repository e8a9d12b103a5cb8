"""Adversarial inputs, one or more of each kind that once ended badly: silent
wrong results, wrong input accepted, raw tracebacks, hangs, valid input
refused, energy created without a word. Each case asserts its outcome: a
named error (the field in the message, no traceback) or a correct run checked
against its invariants. The long cases are marked ``slow``."""

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from reference_models import BouncingBall, ElasticBar, RigidPendulum

import nsga_jax as nj
from nsga_jax._chunks import kept_rows
from nsga_jax._cli import EXIT_FAILED, EXIT_INPUT, EXIT_INTERRUPTED, main
from nsga_jax._folders import RUN_FILES
from nsga_jax._simulate import chunk_plan
from nsga_jax._validation import MAX_STEPS, time_grid
from nsga_jax.scenes import load_scene

BALL = BouncingBall(m=1.0, gravity=9.81, e=0.5)


def error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert err and err[-1].startswith("error: "), err
    assert not any("Traceback" in line for line in err), err
    return err[-1]


# ------------------------------------------------------------ silent wrong results


def test_step_counts_past_two_to_the_31_are_counted_exactly():
    """2**31 and more steps: host integers plan the chunks, no device counter
    passes a chunk's length (the counter logic, not a 2**31-step run)."""
    t0, t1, h, n = time_grid(0.0, 2147.48365, 1e-6)
    assert n == 2_147_483_650 > 2**31
    for total in (2**32 + 10, 2**31 + 1, 12345):
        plan = list(chunk_plan(total, 4096))
        assert sum(count for _, count in plan) == total
        assert all(0 < count <= 4096 for _, count in plan[:3] + plan[-3:])
        assert plan[-1][0] + plan[-1][1] - 1 == total  # the last chunk ends at the last step
    resumed = list(chunk_plan(2**32 + 10, 2**20, done=2**32))
    assert resumed[0] == (2**32 + 1, 10)
    assert MAX_STEPS >= 2**62


def test_a_run_of_more_steps_than_memory_holds_is_refused_with_the_estimate():
    with pytest.raises(nj.ConfigError, match=r"records of 1,000,000,000,000 steps .* GB.*record_every"):
        nj.simulate(BALL, nj.DS(), 0.0, 1.0, 1e-12, [1.0], [0.0])


def test_float32_time_is_t0_plus_k_h_not_accumulated():
    """10**6 steps in float32: the run ends at t = 100 s (it ended at 99.327 s
    when time was accumulated step by step)."""
    sol = nj.simulate(BALL, nj.DS(), 0.0, 100.0, 1e-4, [1.0], [0.0], dtype="float32",
                      saveat=nj.SaveAt(every=100_000))
    assert sol.n_steps == 1_000_000
    assert sol.ts[-1] == 100.0 and sol.ts.dtype == np.float64
    assert abs(float(sol.records.t[-1]) - 100.0) < 1e-4  # the device's own float32 time of the last step


def test_models_refuse_what_their_physics_cannot_mean():
    with pytest.raises(nj.ConfigError, match=r"ElasticBar.n_elements must be an integer >= 1, got 0"):
        ElasticBar(E=900.0, rho=1.0, area=1.0, length=10.0, gap0=1.0, e=0.0, n_elements=0)
    with pytest.raises(nj.ConfigError, match=r"RigidPendulum.side must be \+1 or -1 .*got 0.0"):
        RigidPendulum(m=1.0, length=1.0, gravity=9.81, wall_x=0.3, side=0.0, e=0.5)
    with pytest.raises(nj.ConfigError, match=r"side must be \+1 or -1"):
        RigidPendulum(m=1.0, length=1.0, gravity=9.81, wall_x=0.3, side=0.5, e=0.5)


# ------------------------------------------------------------ wrong input accepted


@pytest.mark.parametrize("kwargs, error, match", [
    ({"h": True}, nj.ConfigError, r"h must be a real number .* got bool True"),
    ({"h": "1e-3"}, nj.ConfigError, r"h must be a real number"),
    ({"chunk_size": 0}, nj.ConfigError, r"chunk_size must be an integer >= 1, got 0"),
    ({"record_every": True}, nj.ConfigError, r"record_every must be an integer >= 1"),
    ({"throw": "yes"}, TypeError, r"throw must be True or False"),
    ({"dtype": "float16"}, nj.ConfigError, r"dtype must be one of 'float64', 'float32'"),
    ({"h": 1e-300}, nj.ConfigError, r"h = 1e-300 s is below the time resolution of float64"),
    ({"t0": 1e9, "t1": 1e9 + 1.0, "h": 1e-9}, nj.ConfigError, r"below the time resolution"),
    ({"h": 1e-5, "dtype": "float32", "t1": 1000.0}, nj.ConfigError, r"below the time resolution of float32"),
    ({"scheme": nj.DS}, TypeError, r"scheme must be a scheme instance.*the class DS \(an instance is needed: DS\(\)\)"),
    ({"scheme": "ds"}, TypeError, r"scheme must be a scheme instance.*got str 'ds'"),
    ({"model": "bouncing_ball"}, TypeError, r"model must be a model instance.*got str"),
    ({"model": BouncingBall}, TypeError, r"model must be a model instance.*the class BouncingBall"),
    ({"q0": "1.0"}, TypeError, r"q0 must be an array of 1 numbers, got str"),
    ({"v0": ["a"]}, TypeError, r"v0 must be an array of 1 numbers"),
    ({"on_chunk": 3}, TypeError, r"on_chunk must be a function or None"),
])
def test_simulate_refuses_by_name(kwargs, error, match):
    args = {"model": BALL, "scheme": nj.DS(), "t0": 0.0, "t1": 1.0, "h": 1e-3, "q0": [1.0], "v0": [0.0], **kwargs}
    with pytest.raises(error, match=match):
        if "record_every" in args:  # kept rows: SaveAt(every=k)
            args["saveat"] = nj.SaveAt(every=args.pop("record_every"))
        nj.simulate(**args)


def test_a_folder_holding_a_killed_run_is_never_mixed_with_a_new_one(tmp_path, capsys):
    out = tmp_path / "run"
    (out / "partial").mkdir(parents=True)
    np.savez(out / "partial" / "chunk_00007.npz", t=np.arange(3.0))  # a killed run's chunk
    args = ["run", "bouncing_ball", "--t-end", "0.2", "--h", "1e-3", "--out", str(out), "--quiet"]
    assert main(args) == EXIT_INPUT
    assert "holds an earlier run (partial)" in error_line(capsys) and (out / "partial" / "chunk_00007.npz").exists()
    assert main(args + ["--overwrite"]) == 0
    data = np.load(out / "trajectory.npz")
    assert data["t"].shape == (201,) and data["t"][-1] == pytest.approx(0.2)  # only this run's 200 steps
    assert not (out / "partial").exists() and json.loads((out / "run.json").read_text())["command"] == "run"


def test_default_output_folder_never_reuses_an_earlier_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    for _ in range(2):
        assert main(["run", "bouncing_ball", "--t-end", "0.05", "--quiet"]) == 0
    assert (tmp_path / "nsga_out" / "bouncing_ball" / "summary.json").exists()
    assert (tmp_path / "nsga_out" / "bouncing_ball_2" / "summary.json").exists()


def test_a_scene_name_is_a_name_even_where_a_folder_of_that_name_exists(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bouncing_ball").mkdir()
    assert main(["run", "bouncing_ball", "--t-end", "0.05", "--out", "bouncing_ball", "--quiet"]) == 0
    assert (tmp_path / "bouncing_ball" / "summary.json").exists()


SWEEP = ["sweep", "bouncing_ball", "--grid", "e=0.3;0.6", "--h", "2e-3", "--set", "t_end=0.2",
         "--batch-size", "1", "--quiet"]


@pytest.mark.parametrize("damage, match", [
    (lambda p: p.write_text(""), r"batch file .*batch_00000.csv holds runs \[\] \(0 rows\)"),
    (lambda p: p.write_text(p.read_text().splitlines()[0] + "\n"), r"\(0 rows\).*incomplete or from another sweep"),
    (lambda p: p.write_text(p.read_text()[: len(p.read_text()) // 2]), r"batch file .*batch_00000.csv"),
])
def test_damaged_batch_files_are_named_not_a_shorter_table(tmp_path, capsys, damage, match):
    out = tmp_path / "s"
    assert main(SWEEP + ["--out", str(out)]) == 0
    damage(out / "batches" / "batch_00000.csv")
    assert main(SWEEP + ["--out", str(out)]) == EXIT_INPUT
    assert_matches(match, error_line(capsys))


def assert_matches(pattern, text):
    import re

    assert re.search(pattern, text), text


def test_a_resume_with_other_settings_names_them(tmp_path, capsys):
    out = tmp_path / "s"
    assert main(SWEEP + ["--out", str(out)]) == 0
    assert main(SWEEP + ["--out", str(out), "--max-records", "50"]) == EXIT_INPUT
    assert_matches(r"differ in max_records: 2000 there, 50 now", error_line(capsys))
    (out / "sweep.json").write_text('{"scene": "bouncing_ball", "gri')  # truncated
    assert main(SWEEP + ["--out", str(out)]) == EXIT_INPUT
    assert_matches(r"sweep.json cannot be read", error_line(capsys))


# ------------------------------------------------------------------ raw tracebacks


@pytest.mark.parametrize("text, match", [
    ('scene = "bouncing_ball"\nparameters = 3\n', r"\[parameters\] must be a table"),
    ('scene = ["bouncing_ball"]\n', r"'scene' must be a string"),
    ('scene = "bouncing_ball"\n[solver]\nh = "fast"\n', r"h \[s\] must be a number"),
    (b'scene = "bouncing_ball"\n# \xff\xfe\n', r"not a UTF-8 text file"),
    ('scene = "bouncing_ball"\n[parameters\n', r"invalid TOML"),
])
def test_malformed_configs_are_named(tmp_path, capsys, text, match):
    path = tmp_path / "c.toml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    assert main(["run", str(path), "--out", str(tmp_path / "o")]) == EXIT_INPUT
    assert_matches(match, error_line(capsys))


def test_output_paths_that_cannot_be_folders_are_named(tmp_path, capsys):
    file = tmp_path / "a_file"
    file.write_text("x")
    assert main(["run", "bouncing_ball", "--out", str(file)]) == EXIT_INPUT
    assert_matches(r"is an existing file, not a folder", error_line(capsys))
    assert main(["run", "bouncing_ball", "--out", str(file / "below")]) == EXIT_INPUT
    assert_matches(r"cannot be written", error_line(capsys))


@pytest.mark.parametrize("args, match", [
    # the largest cube takes the matrix-free path (8 GB) with every scheme; 1000 s of its records fit nowhere
    (["run", "flexible_cube", "--set", "divisions=40", "--scheme", "mj", "--t-end", "1000"],
     r"keeping the records of 33,333,333 steps needs [\d,]+ GB .* beside \d\.\d GB of matrices"),
    (["run", "impacting_bar", "--set", "n_elements=100000"], r"impacting_bar: .* GB estimated for 100,001 coordinates"),
    (["run", "bouncing_ball", "--h", "1e-300"], r"below the time resolution"),
    (["run", "bouncing_ball", "--h", "1e-12", "--t-end", "1"], r"records of 1,000,000,000,000 steps"),
    (["sweep", "bouncing_ball", "--grid", "e=0:1:10000000"], r"10,000,000 runs .* at most 1,000,000"),
    (["convergence", "bouncing_ball", "--h", "1e-2", "--ref", "exact", "--set", "height=0"],
     r"reference \(exact solution\) of observable 'z' is zero at every time"),
    (["identify", "bouncing_ball", "--params", "e", "--data", "measured.csv"], r"'measured.csv' does not exist"),
])
def test_limits_are_refused_before_anything_runs(tmp_path, capsys, args, match):
    start = time.perf_counter()
    assert main([*args, "--out", str(tmp_path / "o")]) == EXIT_INPUT
    assert_matches(match, error_line(capsys))
    assert time.perf_counter() - start < 60  # no compilation, no run


def test_ctrl_c_stops_cleanly_and_says_what_was_kept(tmp_path):
    out = tmp_path / "long"
    proc = subprocess.Popen([sys.executable, "-m", "nsga_jax._cli", "run", "bouncing_ball", "--h", "1e-4",
                             "--t-end", "1e4", "--record-every", "100", "--chunk", "2048", "--out", str(out)],
                            stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "NSGA_JAX_CACHE": "off"})
    deadline = time.time() + 240
    while time.time() < deadline and not list((out / "partial").glob("chunk_*.npz")):  # within FILE_SECONDS
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == EXIT_INTERRUPTED, err[-2000:]
    assert "Traceback" not in err
    kept = kept_rows(out / "partial")
    assert kept >= 20 and f"interrupted: the records of {kept} step(s) (one in every 100) kept in" in err


# ----------------------------------------------------------- energy created silently


def test_energy_created_at_an_impact_is_named_and_strict_fails(tmp_path, capsys):
    out = tmp_path / "box"
    assert main(["run", "rigid_box", "--h", "1e-2", "--out", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "warning: coarse step: a body turns 0.849 rad per step" in err
    assert "warning: energy rise at an impact: the energy rose by" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["energy"]["max_impact_rise"] > 1000.0  # J: 2184 -> 4441 J in one impact step
    assert any(w.startswith("energy rise at an impact") for w in summary["warnings"])
    assert main(["run", "rigid_box", "--h", "1e-2", "--out", str(out), "--overwrite", "--strict",
                 "--quiet"]) == EXIT_FAILED
    assert "error: energy rise at an impact" in capsys.readouterr().err
    assert json.loads((out / "summary.json").read_text())["error"].startswith("energy rise at an impact")


@pytest.mark.parametrize("name, overrides", [
    ("bouncing_ball", {}),
    ("rigid_pendulum", {"t_end": 2.0}),
    ("impacting_bar", {"t_end": 0.8}),
    ("rigid_box", {}),
])
def test_default_runs_keep_their_invariants(name, overrides):
    """Correct runs: no warning, no penetration or joint drift past the
    tolerances, energy never created at an impact (e <= 1)."""
    sol = load_scene(name, overrides).run()
    assert sol.warnings == []
    st = sol.stats
    assert st["max_penetration"] <= 1e-6 and st["max_bilateral_violation_position"] <= 1e-6
    energy = st["energy"]
    assert energy["impact_steps"] > 0
    assert energy["max_impact_rise"] <= 1e-2 * max(abs(energy["initial"]), 1.0)
    assert math.isfinite(energy["final"]) and energy["final"] <= energy["initial"] + 1e-6 * abs(energy["initial"])


def test_run_files_are_what_the_claim_checks(tmp_path):
    """Every file a run writes is one the folder claim knows."""
    out = tmp_path / "r"
    assert main(["run", "bouncing_ball", "--t-end", "0.05", "--out", str(out), "--quiet"]) == 0
    written = {p.name for p in Path(out).iterdir()}
    assert written <= set(RUN_FILES), written - set(RUN_FILES)


def test_batch_files_of_another_sweep_are_never_read_as_this_ones(tmp_path, capsys):
    out = tmp_path / "s"
    assert main(SWEEP + ["--out", str(out)]) == 0
    (out / "sweep.json").unlink()  # batch files without the description of their sweep
    assert main(SWEEP + ["--out", str(out)]) == EXIT_INPUT
    assert_matches(r"holds batch files but sweep.json is missing", error_line(capsys))
    other = tmp_path / "other"
    assert main(["sweep", "bouncing_ball", "--grid", "e=0.4;0.7", *SWEEP[4:], "--out", str(other)]) == 0
    (out / "batches" / "batch_00000.csv").unlink()
    (out / "batches" / "batch_00001.csv").unlink()
    for k in (0, 1):  # another sweep's batches, same run numbers
        (out / "batches" / f"batch_0000{k}.csv").write_bytes((other / "batches" / f"batch_0000{k}.csv").read_bytes())
    (out / "sweep.json").write_text((other / "sweep.json").read_text().replace("0.4", "0.3").replace("0.7", "0.6"))
    assert main(SWEEP + ["--out", str(out)]) == EXIT_INPUT
    assert_matches(r"run 0 has e = 0.4 there, 0.3 in this sweep: it is another sweep's", error_line(capsys))
