"""The paper's four scenes at its middle step sizes: every step converges, no
penetration, bilateral constraints within tolerance."""

import numpy as np
import pytest

from nsga_jax.scenes import load_scene


def check_clean(sol, bilateral_tol=1e-8, penetration_tol=1e-10):
    """Every step converged; what is left of penetration and joint violation is
    within the Newton tolerance (eq. 51 with tol_r = 1e-5 is relative: on the
    soft cube a node that enters the active set at the last iterate can keep
    ~1e-8 m, i.e. 1e-7 of the cube's size)."""
    stats = sol.stats
    assert stats["failed_steps"] == 0
    assert stats["max_penetration"] <= penetration_tol
    assert stats["max_bilateral_violation_position"] <= bilateral_tol
    assert stats["max_bilateral_violation_velocity"] <= bilateral_tol


def test_rigid_box_paper_run():
    sol = load_scene("rigid_box", {"h": 1e-3}).run()  # T = 0.69 s, the paper's window
    check_clean(sol)
    impacts = sol.impulse[:, 6:].sum(axis=1) > 0
    assert impacts.any()
    energy = sol.observables["energy"]
    assert energy[-1] < energy[0]  # e = 0.8 dissipates
    # DS needs few iterations with the nonlinear rigidity constraints (paper Fig. 3)
    assert stats_max(sol) <= 4


def stats_max(sol):
    return max(sol.stats["iterations"][k]["max"] for k in ("smooth", "position", "velocity"))


def test_flexible_pendulum_paper_run():
    sol = load_scene("flexible_pendulum", {"h": 1e-4}).run()  # T = 0.35 s
    check_clean(sol)
    assert (sol.impulse[:, -1] > 0).any()  # the tip reaches the wall
    assert stats_max(sol) <= 3
    # energy is conserved by the fall (no contact yet) to within the integrator's error
    energy, first = sol.observables["energy"], np.argmax(sol.impulse[:, -1] > 0)
    scale = 7800 * 1e-4 * 1.0 * 9.81 * 0.5  # m g L/2: the potential energy released
    assert np.abs(energy[:first]).max() < 1e-3 * scale


@pytest.mark.parametrize("h", [3e-5])
def test_flexible_cube_impact_window(h):
    # the paper's cube, started just above the floor at its impact speed
    # sqrt(2 g 0.3) = 2.43 m/s so that a short window covers the impact
    scene = load_scene("flexible_cube", {"h": h, "t_end": 0.006, "height": 0.0505, "velocity": -2.43})
    sol = scene.run()
    check_clean(sol, penetration_tol=1e-6 * 0.1)
    assert (sol.impulse > 0).any()
    assert sol.observables["x1_vz"][-1] > -2.43  # the bottom corner has been stopped
    assert stats_max(sol) <= 3


@pytest.mark.slow
def test_flexible_cube_paper_run():
    sol = load_scene("flexible_cube", {"h": 1e-4}).run()  # T = 0.3 s, about 30 s on 2 cores
    check_clean(sol, penetration_tol=1e-6 * 0.1)
    assert sol.observables["x1_uz"].min() == pytest.approx(-0.3, abs=2e-3)  # falls onto the floor
