"""Sweeps: the grid, agreement with single runs, resuming after a kill, and
sharding over two (forced) CPU devices giving the same table."""

import csv
import os
import re
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from nsga_jax._batch import broadcast_members, member_mesh, needs_bounded_lapack_batches
from nsga_jax._cli import main
from nsga_jax._metrics import relative_l1_error
from nsga_jax._results import ConfigError
from nsga_jax._sweep import parse_grid, sweep
from nsga_jax.scenes import REGISTRY, load_scene

ROOT = Path(__file__).resolve().parents[1]
TIMING = {"batch_wall_s"}


def table(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return [{k: v for k, v in r.items() if k not in TIMING} for r in csv.DictReader(f)]


def assert_same_table(a: Path, b: Path) -> None:
    """The same rows, numbers to 1e-12 (member splits may batch LAPACK calls differently)."""
    a, b = table(a), table(b)
    assert len(a) == len(b)
    for ra, rb in zip(a, b):
        assert ra.keys() == rb.keys()
        for k in ra:
            try:
                assert float(ra[k]) == pytest.approx(float(rb[k]), rel=1e-12, abs=1e-15), k
            except ValueError:
                assert ra[k] == rb[k], k


def run_python(code: str, env_extra: dict | None = None) -> subprocess.CompletedProcess:
    env = {**os.environ, **(env_extra or {})}
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=600)


def test_parse_grid():
    grid = parse_grid("e=0:1:11, E=800:1000:5")
    assert list(grid) == ["e", "E"]
    np.testing.assert_allclose(grid["e"], np.linspace(0, 1, 11))
    np.testing.assert_allclose(grid["E"], [800, 850, 900, 950, 1000])
    np.testing.assert_allclose(parse_grid("e=0.2;0.5")["e"], [0.2, 0.5])
    for bad in ("e", "e=0:1", "e=a:b:3", "e=0:1:0", "", "e=1,e=2"):
        with pytest.raises(ConfigError):
            parse_grid(bad)


@pytest.mark.parametrize("grid, message", [
    ({"n_elements": [10, 20]}, "structural parameter"),
    ({"nope": [1.0]}, "not a parameter"),
    ({"e": [0.5, 1.5]}, r"e must be in \[0, 1\]"),
])
def test_bad_sweeps_refused_before_running(grid, message):
    with pytest.raises(ConfigError, match=message):
        sweep("impacting_bar", grid)


def test_rows_equal_single_runs(tmp_path):
    res = sweep("bouncing_ball", {"e": [0.6, 0.9]}, hs=[1e-3, 2.5e-3], overrides={"t_end": 1.5},
                out=tmp_path, batch_size=3)
    assert [(r["e"], r["h"]) for r in res.rows] == [(0.6, 1e-3), (0.6, 2.5e-3), (0.9, 1e-3), (0.9, 2.5e-3)]
    for row in res.rows:
        scene = load_scene("bouncing_ball", {"e": row["e"], "h": row["h"], "t_end": 1.5})
        sol = scene.run()
        exact = scene.exact(sol.ts)
        assert row["n_steps"] == sol.n_steps and row["result"] == "successful"
        assert row["error_z"] == pytest.approx(relative_l1_error(sol.observables["z"], exact["z"]), rel=1e-10)
        assert row["z_final"] == pytest.approx(sol.observables["z"][-1], rel=1e-10, abs=1e-12)
        assert row["solves_per_step_mean"] == pytest.approx(sol.stats["iterations"]["linear_solves"]["mean"])
    assert (tmp_path / "sweep.png").stat().st_size > 0
    assert len(table(tmp_path / "sweep.csv")) == 4


@pytest.mark.parametrize("name", sorted(REGISTRY))
def test_member_axis_leaves_sizes_unchanged(name):
    """A batch stacks every model leaf along a leading member axis: the sizes
    the time loop reads (records, chunk length) must not see that axis."""
    model = load_scene(name).model
    members = broadcast_members(model, 3)
    sizes = ("n_dof", "n_bilateral", "n_unilateral", "n_constraints")
    assert [getattr(members, k) for k in sizes] == [getattr(model, k) for k in sizes]


def test_rigid_box_sweep_equals_single_runs():
    """Fewer members than the box has contacts: its records and gaps come out
    of the batch with their own sizes, and equal single runs."""
    settings = {"z0": 0.3, "t_end": 0.3, "h": 2e-3}
    res = sweep("rigid_box", {"e": [0.5, 0.8]}, overrides=settings, batch_size=2)
    for row in res.rows:
        sol = load_scene("rigid_box", {**settings, "e": row["e"]}).run()
        assert row["n_steps"] == sol.n_steps == 150 and row["failed_steps"] == 0
        assert row["gap_1_min"] == pytest.approx(sol.gap[:, 1].min(), abs=1e-12)
        for name, y in sol.observables.items():
            if y.ndim > 1:
                continue
            assert row[f"{name}_final"] == pytest.approx(y[-1], rel=1e-9, abs=1e-9), name
            assert row[f"{name}_min"] == pytest.approx(y.min(), rel=1e-9, abs=1e-9), name
        assert "gap_7_final" in row


KILLED_SWEEP = """
import os, signal
import jax
jax.config.update("jax_enable_x64", True)
from nsga_jax._sweep import sweep

def kill_after_first(k, rows):
    if k == 0:
        os.kill(os.getpid(), signal.SIGKILL)

sweep("bouncing_ball", {{"e": [0.3, 0.6, 0.9]}}, hs=[2e-3], overrides={{"t_end": 1.0}}, out={out!r},
      batch_size=2, on_batch=kill_after_first)
"""


def test_killed_sweep_resumes_to_the_same_table(tmp_path):
    killed = tmp_path / "killed"
    proc = run_python(KILLED_SWEEP.format(out=str(killed)))
    assert proc.returncode == -9, proc.stderr[-2000:]
    assert (killed / "batches" / "batch_00000.csv").exists()
    assert not (killed / "sweep.csv").exists()

    resumed_batches = []
    sweep("bouncing_ball", {"e": [0.3, 0.6, 0.9]}, hs=[2e-3], overrides={"t_end": 1.0}, out=killed,
          batch_size=2, on_batch=lambda k, rows: resumed_batches.append(k))
    assert resumed_batches == [1]  # batch 0 was not run again
    whole = tmp_path / "whole"
    sweep("bouncing_ball", {"e": [0.3, 0.6, 0.9]}, hs=[2e-3], overrides={"t_end": 1.0}, out=whole, batch_size=2)
    assert table(killed / "sweep.csv") == table(whole / "sweep.csv")

    with pytest.raises(ConfigError, match="holds another sweep"):
        sweep("bouncing_ball", {"e": [0.3]}, out=killed)


SHARDED_SWEEP = """
import jax
jax.config.update("jax_enable_x64", True)
from nsga_jax._batch import needs_bounded_lapack_batches, member_mesh
from nsga_jax._sweep import sweep
assert len(jax.devices()) == 2, jax.devices()
assert needs_bounded_lapack_batches(member_mesh())
sweep({name!r}, {grid!r}, hs={hs!r}, overrides={overrides!r}, out={out!r}, batch_size=4)
"""

SHARDED_CASES = {
    # linear: constant iteration matrices, block-eliminated once per member
    "impacting_bar": ({"e": [0.0, 0.5, 1.0]}, [1e-3, 2e-3], {"t_end": 0.4}),
    # nonlinear: an LU factorisation per Newton iteration, the batch that deadlocked
    # jaxlib 0.10 on 2 CPU devices before its LAPACK calls were bounded
    "flexible_pendulum": ({"e": [0.0, 0.4, 0.8, 1.0]}, [1e-4], {"t_end": 0.005}),
}


@pytest.mark.parametrize("name", list(SHARDED_CASES))
def test_sharded_sweep_equals_unsharded(tmp_path, name):
    grid, hs, overrides = SHARDED_CASES[name]
    sharded = tmp_path / "sharded"
    proc = run_python(SHARDED_SWEEP.format(name=name, grid=grid, hs=hs, overrides=overrides, out=str(sharded)),
                      {"XLA_FLAGS": "--xla_force_host_platform_device_count=2"})
    assert proc.returncode == 0, proc.stderr[-3000:]
    single = tmp_path / "single"
    sweep(name, grid, hs=hs, overrides=overrides, out=single, batch_size=4)
    assert len(table(sharded / "sweep.csv")) == len(grid["e"]) * len(hs)
    assert_same_table(sharded / "sweep.csv", single / "sweep.csv")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def sweep_on_two_processes(outs: tuple[Path, Path], *args: str) -> list[subprocess.CompletedProcess]:
    """``nsga-jax sweep ...`` as two processes joined by jax.distributed over
    loopback, one CPU device each, process i writing to ``outs[i]`` (one
    folder for both is a shared file system; two are two hosts' own disks)."""
    port = free_port()
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    cmd = [sys.executable, "-m", "nsga_jax._cli", "sweep", *args, "--quiet", "--no-cache",
           "--coordinator", f"127.0.0.1:{port}", "--num-processes", "2"]
    procs = [subprocess.Popen([*cmd, "--out", str(outs[i]), "--process-id", str(i)], cwd=ROOT, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for i in range(2)]
    done = []
    for p in procs:
        try:
            stdout, stderr = p.communicate(timeout=300)
        except subprocess.TimeoutExpired:
            for q in procs:
                q.kill()
            raise
        done.append(subprocess.CompletedProcess(p.args, p.returncode, stdout, stderr))
    return done


ARGS = ["bouncing_ball", "--grid", "e=0.3;0.6;0.9", "--h", "2e-3", "--set", "t_end=0.5", "--batch-size", "2"]


def test_sweep_over_two_processes_equals_one_process(tmp_path):
    shared = tmp_path / "shared"
    procs = sweep_on_two_processes((shared, shared), *ARGS)
    for p in procs:
        assert p.returncode == 0, p.stderr[-3000:]
    assert "3 runs on 2 device(s)" in procs[0].stdout and "3 runs on 2 device(s)" in procs[1].stdout
    assert "wrote" in procs[0].stdout and "process 0 writes the files" in procs[1].stdout
    single = tmp_path / "single"
    assert main(["sweep", *ARGS, "--out", str(single), "--quiet"]) == 0
    assert_same_table(shared / "sweep.csv", single / "sweep.csv")

    # another sweep in that folder: process 0 refuses it, and so does process 1 (it does not wait for it)
    other = [*ARGS[:2], "e=0.4", *ARGS[3:]]
    for p in sweep_on_two_processes((shared, shared), *other):
        assert p.returncode == 2 and "holds another sweep" in p.stderr, p.stderr[-3000:]


def test_two_processes_resume_as_process_0_decides(tmp_path):
    """Each process with its own folder (two hosts' disks): process 1 never
    sees the batch files, yet skips the batch process 0 has, instead of
    running it alone and waiting for process 0 in it."""
    own = (tmp_path / "host0", tmp_path / "host1")
    for p in sweep_on_two_processes(own, *ARGS):
        assert p.returncode == 0, p.stderr[-3000:]
    assert not own[1].exists()  # process 1 wrote nothing
    whole = own[0] / "sweep.csv"
    kept = tmp_path / "whole.csv"
    kept.write_bytes(whole.read_bytes())
    first = own[0] / "batches" / "batch_00000.csv"
    written = first.stat().st_mtime_ns
    (own[0] / "batches" / "batch_00001.csv").unlink()
    whole.unlink()
    procs = sweep_on_two_processes(own, *ARGS)
    for p in procs:
        assert p.returncode == 0, p.stderr[-3000:]
    assert first.stat().st_mtime_ns == written  # batch 0 was not run again
    assert_same_table(whole, kept)
    assert "1 runs on 2 device(s)" in procs[1].stdout  # process 1 holds the rows it ran


@pytest.mark.parametrize("argv, message", [
    (["--coordinator", "127.0.0.1:1234"], "go together"),
    (["--coordinator", "127.0.0.1", "--num-processes", "2", "--process-id", "0"], "HOST:PORT"),
    (["--coordinator", "127.0.0.1:0", "--num-processes", "2", "--process-id", "0"], "HOST:PORT"),
    (["--coordinator", "127.0.0.1:1234", "--num-processes", "0", "--process-id", "0"], "num_processes"),
    (["--coordinator", "127.0.0.1:1234", "--num-processes", "2", "--process-id", "2"],
     r"process_id must be .* \[0, 1\]"),
    (["--coordinator", "127.0.0.1:1234", "--num-processes", "2", "--process-id", "0", "--devices", "1"],
     "--devices applies to one process"),
])
def test_bad_process_settings_refused_before_joining(tmp_path, capsys, argv, message):
    assert main(["sweep", "bouncing_ball", "--grid", "e=0.5", "--out", str(tmp_path / "s"), *argv]) == 2
    assert re.search(message, capsys.readouterr().err)


def test_only_a_batch_over_several_cpu_devices_bounds_its_lapack_calls():
    import jax

    assert not needs_bounded_lapack_batches(None)
    assert not needs_bounded_lapack_batches(member_mesh(jax.devices()[:1]))


def test_cli_sweep(tmp_path, capsys):
    out = tmp_path / "s"
    rc = main(["sweep", "bouncing_ball", "--grid", "e=0.5;0.9", "--h", "2e-3", "--set", "t_end=0.5",
               "--out", str(out), "--quiet"])
    assert rc == 0
    rows = table(out / "sweep.csv")
    assert [float(r["e"]) for r in rows] == [0.5, 0.9]
    assert (out / "sweep.png").exists() and (out / "sweep.json").exists()
    assert main(["sweep", "bouncing_ball", "--grid", "mass=-1;1", "--out", str(tmp_path / "bad")]) == 2
    assert "mass" in capsys.readouterr().err


def test_failed_runs_are_reported(tmp_path, capsys):
    res = sweep("rigid_pendulum", {"e": [0.5, 0.9]}, hs=[0.05], overrides={"t_end": 1.0, "max_iter": 1})
    assert len(res.failed) == 2
    assert all(r["result"] != "successful" and r["failed_steps"] > 0 for r in res.failed)
    rc = main(["sweep", "rigid_pendulum", "--grid", "e=0.5", "--h", "0.05", "--set", "t_end=1.0", "--set", "max_iter=1",
               "--out", str(tmp_path / "f"), "--quiet"])
    assert rc == 0
    assert "warning: run 0 (e=0.5, h=0.05) failed at 20 step(s): smooth_max_iter" in capsys.readouterr().err


def test_bad_sweep_settings():
    with pytest.raises(ConfigError, match="max_records"):
        sweep("bouncing_ball", {"e": [0.5]}, max_records=0)
    with pytest.raises(ConfigError, match="at least one device"):
        sweep("bouncing_ball", {"e": [0.5]}, devices=[])
    with pytest.raises(ConfigError, match="batch_size"):
        sweep("bouncing_ball", {"e": [0.5]}, batch_size=0)


def test_cli_sweep_refuses_a_bad_step_size(tmp_path, capsys):
    assert main(["sweep", "bouncing_ball", "--grid", "e=0.5", "--h", "abc", "--out", str(tmp_path / "s")]) == 2
    assert "--h expects comma-separated numbers" in capsys.readouterr().err


def test_a_member_whose_exact_motion_is_zero_keeps_the_sweep_going(tmp_path):
    """A block that sticks from rest (μ > tan 0.3 = 0.309) has s(t) = 0 exactly:
    eq. 52 is undefined for it, so its relative error is left empty (the plot
    skips it) and its largest absolute error is given; the sliding member keeps
    eq. 52."""
    res = sweep("incline", {"mu": [0.1, 0.5]}, overrides={"t_end": 0.3}, out=tmp_path / "s")
    sliding, sticking = sorted(res.rows, key=lambda r: r["mu"])
    assert sliding["error_s"] is not None and 0.0 <= sliding["error_s"] < 1e-2
    assert sticking["error_s"] is None and sticking["error_ds"] is None
    assert sticking["abs_error_s"] < 1e-12 and sticking["abs_error_ds"] < 1e-12
    assert sliding["abs_error_s"] > 0.0
    assert (tmp_path / "s" / "sweep.png").stat().st_size > 1000
