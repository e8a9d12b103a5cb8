"""Rigid pendulum: a nonlinear bilateral constraint and a wall."""

import numpy as np
import pytest

from nsga_jax.scenes import load_scene


@pytest.fixture(scope="module")
def long_run():
    scene = load_scene("rigid_pendulum", {"t_end": 10.0, "h": 1e-3, "e": 0.7})
    return scene, scene.run()


def test_rod_constraint_holds_without_drift(long_run):
    scene, sol = long_run
    assert sol.n_steps == 10_000
    assert sol.stats["failed_steps"] == 0
    # position level: |x|^2 = l^2 after every step (no drift over 1e4 steps)
    assert np.abs(sol.observables["constraint"]).max() < 1e-8
    assert np.abs(np.asarray(sol.records.bilateral)).max() < 1e-8
    # velocity level: g_q v = x vx + y vy = 0 after every step
    radial_velocity = (sol.q * sol.v).sum(axis=1) / scene.parameters["length"]
    assert np.abs(radial_velocity).max() < 1e-10
    # no drift: the late violations are no larger than the early ones' bound
    late = np.abs(sol.observables["constraint"][-1000:]).max()
    assert late < 1e-8


def test_wall_impacts_obey_newton_law(long_run):
    scene, sol = long_run
    e, side = scene.parameters["e"], float(np.sign(sol.q[0, 0] - scene.parameters["wall_x"]))  # where it starts
    impacts = np.nonzero(sol.impulse[:, 1] > 0)[0]
    assert len(impacts) >= 4
    assert sol.gap.min() >= -1e-12
    for k in impacts:
        before, after = side * sol.v[k - 1, 0], side * sol.v[k, 0]
        if before < 0:  # an approach: g_q v_{n+1} = -e g_q v_n (eq. 32a, contact active)
            assert after == pytest.approx(-e * before, rel=1e-8, abs=1e-10)
        assert after >= -1e-10  # never moving into the wall after the step


def test_energy_does_not_increase(long_run):
    scene, sol = long_run
    energy = sol.observables["energy"]
    e0 = energy[0]
    # smooth phases: generalized-α error only; never above the initial energy
    assert energy.max() <= e0 + 1e-6 * abs(e0)
    # each impact dissipates (e < 1)
    for k in np.nonzero(sol.impulse[:, 1] > 0)[0]:
        assert energy[k] < energy[k - 1]
    assert energy[-1] < e0
