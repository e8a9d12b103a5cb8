"""Bouncing ball against its exact (event-driven) solution."""

import numpy as np
import pytest

from nsga_jax._exact import bouncing_ball, bouncing_ball_impacts
from nsga_jax._metrics import observed_order, relative_l1_error
from nsga_jax.scenes import load_scene

H0, G = 1.0, 9.81


def run(h, t_end, e=0.8, **extra):
    return load_scene("bouncing_ball", {"h": h, "t_end": t_end, "e": e, **extra}).run()


def test_exact_solution_conserves_energy_between_impacts():
    t = np.linspace(0.0, 0.45, 50)  # before the first impact
    z, v = bouncing_ball(t, H0, 0.0, G, 0.8)
    assert np.allclose(0.5 * v**2 + G * z, G * H0)
    times, speeds, t_rest = bouncing_ball_impacts(H0, 0.0, G, 0.5, 10.0)
    assert times[0] == pytest.approx(np.sqrt(2 * H0 / G))
    assert np.allclose(speeds[1:] / speeds[:-1], 0.5)
    assert times[-1] < t_rest


@pytest.mark.parametrize("h", [2e-3, 1e-3, 2.5e-4])
def test_first_impact_within_one_step(h):
    sol = run(h, 0.6)
    first = np.nonzero(sol.impulse[:, 0] > 0)[0][0]
    t_impact = np.sqrt(2 * H0 / G)
    # the impact is caught by the step whose interval contains it
    assert t_impact <= sol.ts[first] + 1e-12
    assert sol.ts[first] - t_impact <= h


def test_apex_heights_follow_restitution():
    e, h = 0.8, 1e-3
    sol = run(h, 3.0, e)
    z = sol.q[:, 0]
    impacts = np.nonzero(sol.impulse[:, 0] > 0)[0]
    apexes = [z[a:b].max() for a, b in zip(impacts[:-1], impacts[1:]) if b - a > 2]
    assert len(apexes) >= 4
    expected = H0 * e ** (2 * np.arange(1, len(apexes) + 1))
    # O(h): the impact instant is known to within one step, at impact speed <= sqrt(2 g h0)
    assert np.all(np.abs(np.array(apexes) - expected) <= 2 * np.sqrt(2 * G * H0) * h)


@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_no_penetration_after_any_step(e):
    sol = run(1e-3, 3.0, e)
    # the position sub-problem projects onto g >= 0; what remains is round-off
    assert sol.gap.min() >= -1e-12
    assert sol.stats["failed_steps"] == 0


def test_impact_law_holds_at_impact_steps():
    e = 0.6
    sol = run(1e-3, 1.0, e)
    k = np.nonzero(sol.impulse[:, 0] > 0)[0][0]
    # discrete Newton law (eq. 32a) on the active contact: v_{n+1} = -e v_n
    assert sol.v[k, 0] == pytest.approx(-e * sol.v[k - 1, 0], rel=1e-8)


def test_first_order_convergence_of_position():
    hs = [4e-3, 2e-3, 1e-3, 5e-4]
    errors = []
    for h in hs:
        sol = run(h, 1.5)
        z_exact, _ = bouncing_ball(sol.ts, H0, 0.0, G, 0.8)
        errors.append(relative_l1_error(sol.q[:, 0], z_exact))
    order = observed_order(hs, errors)
    assert 0.8 <= order <= 1.5, (order, errors)
    assert errors[-1] < 2e-3
