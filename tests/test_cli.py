"""The command line: run writes trajectory, summary and plots; bad input exits 2."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nsga_jax._chunks import load_chunks
from nsga_jax._cli import main
from nsga_jax.scenes import REGISTRY, load_scene

CONFIGS = Path(__file__).resolve().parents[1] / "nsga_jax" / "configs"


def test_run_writes_results(tmp_path, capsys):
    out = tmp_path / "ball"
    rc = main(["run", "bouncing_ball", "--t-end", "1.0", "--h", "2e-3", "--set", "e=0.5",
               "--out", str(out), "--chunk", "128", "--quiet"])
    assert rc == 0
    summary = json.loads((out / "summary.json").read_text())
    for key in ("scene", "scheme", "h", "n_steps", "wall_time_s", "compile_time_s", "failed_steps",
                "max_penetration", "max_bilateral_violation_position", "max_bilateral_violation_velocity"):
        assert key in summary
    assert summary["n_steps"] == 500 and summary["parameters"]["e"] == 0.5
    for sub in ("smooth", "position", "velocity", "linear_solves"):
        assert set(summary["iterations"][sub]) == {"mean", "max"}
    data = np.load(out / "trajectory.npz")
    for key in ("t", "q", "v", "z", "vz"):
        assert key in data
    assert data["q"].shape == (501, 1)
    assert (out / "observables.png").stat().st_size > 1000
    assert (out / "iterations.png").stat().st_size > 1000
    assert not (out / "partial").exists()
    assert "500 steps" in capsys.readouterr().out


def test_run_names_the_setting_of_its_scheme(tmp_path, capsys):
    """The first line names θ for Moreau–Jean and ρ∞ for the generalized-α schemes."""
    for scheme, setting, other in (("mj", "theta = 0.5", "rho_inf"), ("ds", "rho_inf = ", "theta")):
        assert main(["run", "bouncing_ball", "--t-end", "0.01", "--scheme", scheme,
                     "--out", str(tmp_path / scheme)]) == 0
        first = capsys.readouterr().err.splitlines()[0]
        assert setting in first and other not in first, first


def _cli(args: list[str], cache) -> dict:
    env = {**os.environ, "NSGA_JAX_CACHE": str(cache)}
    proc = subprocess.run([sys.executable, "-m", "nsga_jax._cli", *args, "--quiet"], env=env, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = Path(args[args.index("--out") + 1])
    return json.loads((out / "summary.json").read_text())


def test_later_runs_load_compiled_programs_from_the_cache(tmp_path):
    cache = tmp_path / "cache"
    first = _cli(["run", "bouncing_ball", "--t-end", "0.5", "--out", str(tmp_path / "a")], cache)
    # programs compiling faster than MIN_COMPILE_SECONDS are not written (the
    # ball's preparation may or may not be, from one run to the next); the time
    # loop's chunk (seconds) always is, and a run that missed it would add one
    def chunk_entries():
        return sorted(p.name for p in cache.iterdir() if p.name.startswith("jit_run_chunk"))

    entries = chunk_entries()
    assert entries
    # another process, another h and restitution: the same programs, loaded
    second = _cli(["run", "bouncing_ball", "--t-end", "0.5", "--h", "2e-3", "--set", "e=0.5",
                   "--out", str(tmp_path / "b")], cache)
    assert chunk_entries() == entries
    assert second["n_steps"] == 250 and first["n_steps"] == 500
    # --no-cache neither reads nor writes it
    _cli(["run", "bouncing_ball", "--t-end", "0.5", "--dtype", "float32", "--no-cache",
          "--out", str(tmp_path / "c")], cache)
    assert chunk_entries() == entries


def test_chunks_are_written_as_they_finish(tmp_path):
    from nsga_jax._output import chunk_writer

    out = tmp_path / "partial_run"
    scene = load_scene("bouncing_ball", {"t_end": 1.0, "h": 1e-2})
    sol = scene.run(chunk_size=30, on_chunk=chunk_writer(out))
    partial = load_chunks(out)
    assert len(list((out / "partial").glob("*.npz"))) == 4
    np.testing.assert_array_equal(partial["q"], sol.q[1:])


def test_bad_input_exits_2(tmp_path, capsys):
    assert main(["run", "bouncing_ball", "--set", "e=1.5", "--out", str(tmp_path)]) == 2
    assert "e must be in [0, 1], got 1.5" in capsys.readouterr().err
    assert main(["run", "bouncing_ball", "--rho-inf", "2", "--out", str(tmp_path)]) == 2
    assert "rho_inf must be in [0, 1]" in capsys.readouterr().err
    assert main(["run", "no_such_scene"]) == 2
    assert "unknown scene" in capsys.readouterr().err


def test_failure_exit_code_and_no_throw(tmp_path, capsys):
    out = tmp_path / "pend"
    args = ["run", "rigid_pendulum", "--t-end", "1.0", "--set", "max_iter=1", "--out", str(out), "--quiet"]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert "position correction" in err and "step" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["failed_steps"] == 1 and summary["error"]
    assert main(args + ["--no-throw"]) == 2  # the folder holds that run: never mixed with another
    assert "holds an earlier run" in capsys.readouterr().err
    assert main(args + ["--no-throw", "--overwrite"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["failed_steps"] >= 1 and summary["n_steps"] == 1000 and summary["error"] is None


@pytest.mark.parametrize("name", sorted(REGISTRY))
def test_shipped_configs_match_scene_defaults(name):
    path = CONFIGS / f"{name}.toml"
    assert path.read_text() == REGISTRY[name].default_toml()
    scene = load_scene(path)
    assert scene.parameters == {k: p.default for k, p in REGISTRY[name].parameters.items()}


def test_scenes_listing(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    for name in REGISTRY:
        assert name in out
