"""The elastic bar of the paper's §4.2 (linear model, one contact)."""

import numpy as np
import pytest

from nsga_jax.scenes import load_scene

L, E, RHO, V0, D0 = 10.0, 900.0, 1.0, 10.0, 5.005
C = np.sqrt(E / RHO)  # wave speed, 30 m/s
MASS = RHO * 1.0 * L


@pytest.fixture(scope="module")
def bar():
    return load_scene("impacting_bar", {"h": 1e-3}).run()


def test_linear_problem_needs_one_newton_iteration(bar):
    it = bar.iterations[1:]
    # linear: one solve per sub-problem that has work to do, none when the
    # starting residual is already zero (free flight, inactive contact)
    assert it.max() == 1
    in_contact = bar.impulse[1:, 0] > 0
    assert np.all(it[in_contact, 1] == 1) and np.all(it[in_contact, 2] == 1)
    assert bar.stats["failed_steps"] == 0


def test_tip_never_penetrates(bar):
    assert bar.observables["tip_gap"].min() >= -1e-12
    assert bar.gap.min() >= -1e-12


def test_contact_duration_and_onset(bar):
    h = bar.h
    contact = np.nonzero(bar.impulse[:, 0] > 0)[0]
    t_on, t_off = bar.ts[contact[0]], bar.ts[contact[-1]]
    assert D0 / V0 <= t_on + 1e-12 and t_on - D0 / V0 <= h
    assert abs((t_off - t_on + h) - 2 * L / C) <= 3 * h  # 0.667 s
    assert np.all(np.diff(contact) == 1)  # one uninterrupted contact phase


def test_rebound_velocity_and_impulse(bar):
    total_impulse = bar.impulse[:, 0].sum()
    assert total_impulse == pytest.approx(2 * MASS * V0, rel=1e-2)  # 200 N s
    mean_velocity = bar.v[-1].mean()  # rigid-body velocity after separation
    assert mean_velocity == pytest.approx(-V0, rel=1e-2)


def test_contact_force_is_the_wave_force(bar):
    force = bar.observables["tip_force"]
    plateau = force[(bar.ts > 0.6) & (bar.ts < 1.1)]
    assert np.median(plateau) == pytest.approx(E * 1.0 / C * V0, rel=1e-3)  # 300 N


def test_lumped_mass_variant_runs():
    sol = load_scene("impacting_bar", {"h": 2e-3, "mass_matrix": "lumped"}).run()
    assert sol.stats["failed_steps"] == 0
    assert sol.iterations.max() == 1
    assert sol.impulse[:, 0].sum() == pytest.approx(200.0, rel=2e-2)
