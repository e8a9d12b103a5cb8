"""Step-size studies: vmap over h, references, eq. 52 errors, the CLI."""

import numpy as np
import pytest

from nsga_jax._cli import main
from nsga_jax._studies import make_reference, run_step_sizes, slopes, study
from nsga_jax.scenes import load_scene


@pytest.mark.timeout(300)
@pytest.mark.parametrize("name", ["bouncing_ball", "impacting_bar"])
def test_vmap_over_step_sizes_equals_separate_runs(name):
    scene = load_scene(name, {"t_end": 1.0})
    hs = [1e-3, 1.25e-3, 2e-3]
    separate = run_step_sizes(scene, hs, mode="separate")
    for _ in range(2):  # a second execution once deadlocked XLA's CPU scheduler
        batched = run_step_sizes(scene, hs, mode="padded")
    for a, b in zip(batched, separate):
        assert a.n_steps == b.n_steps
        np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-12 * max(1.0, np.abs(b.q).max()))
        np.testing.assert_allclose(a.v, b.v, rtol=0, atol=1e-10 * max(1.0, np.abs(b.v).max()))
        np.testing.assert_array_equal(a.iterations, b.iterations)


def test_ball_convergence_order_against_exact():
    ref = make_reference("bouncing_ball", {"t_end": 1.5}, "exact")
    rows = study("bouncing_ball", ["ds"], [4e-3, 2e-3, 1e-3, 5e-4], ref, {"t_end": 1.5}, mode="padded")
    order = slopes(rows)[("ds", "z")]
    assert 0.8 <= order <= 1.5


def test_reference_run_and_grid_sampling():
    ref = make_reference("impacting_bar", {"t_end": 0.6}, 2.5e-4)
    rows = study("impacting_bar", ["ds", "mj"], [1e-3, 2e-3], ref, {"t_end": 0.6}, mode="separate")
    assert len(rows) == 4
    for r in rows:
        assert r.failed_steps == 0
        assert all(0.0 <= e < 0.2 for e in r.errors.values())
    # halving h reduces DS's error of the tip displacement
    ds = [r for r in rows if r.scheme == "ds"]
    assert ds[0].errors["tip_u"] < ds[1].errors["tip_u"]


def test_convergence_cli_writes_table_and_plots(tmp_path, capsys):
    out = tmp_path / "conv"
    rc = main(["convergence", "bouncing_ball", "--scheme", "ds,cs", "--h", "2e-3,1e-3", "--ref", "exact",
               "--t-end", "1.0", "--out", str(out)])
    assert rc == 0
    text = (out / "study.csv").read_text().splitlines()
    assert text[0].startswith("scheme,h,n_steps,batch_size,wall_time_s")
    assert len(text) == 5
    for png in ("convergence.png", "iterations.png", "work_precision.png"):
        assert (out / png).stat().st_size > 1000
    assert main(["convergence", "bouncing_ball", "--h", "1e-3", "--ref-h", "2e-3", "--out", str(out)]) == 2
    assert "--ref-h must be smaller" in capsys.readouterr().err
