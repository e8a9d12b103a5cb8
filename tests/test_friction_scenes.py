"""Friction in the built-in scenes: the ``mu`` parameter, the spinning ball,
the block on an incline and Housner's rocking block, against exact results
(Coulomb's sliding law, the conservation of angular momentum about a
sticking contact point, Housner's impact ratio). Every run checks that the
energy never grows."""

import numpy as np
import pytest

import nsga_jax
from nsga_jax._cli import main
from nsga_jax._exact import (
    housner_ratio,
    incline,
    match_impacts,
    resolvable_impacts,
    rocking_impact_times,
    rocking_impacts,
)
from nsga_jax.scenes import configure, load_scene

FRICTION_SCENES = ["bouncing_ball", "rigid_box", "flexible_cube", "incline", "rocking_block"]


def energy_never_grows(sol, tol=1e-9):
    energy = np.asarray(sol.observables["energy"])
    assert np.diff(energy).max() <= tol * max(1.0, np.abs(energy).max())


# ------------------------------------------------------------------ parameters

@pytest.mark.parametrize("name", FRICTION_SCENES)
def test_negative_mu_is_refused_naming_the_field(name, no_compilation):
    with pytest.raises(nsga_jax.ConfigError, match=r"mu must be in \[0, inf\).*got -0.1"):
        configure(name, {"mu": -0.1})


def test_negative_mu_from_the_command_line_exits_2(tmp_path, capsys, no_compilation):
    assert main(["run", "incline", "--set", "mu=-1", "--out", str(tmp_path / "run")]) == 2
    assert "mu must be in [0, inf)" in capsys.readouterr().err
    path = tmp_path / "ball.toml"
    path.write_text('scene = "bouncing_ball"\n[parameters]\nmu = -0.5\n')
    with pytest.raises(nsga_jax.ConfigError, match=r"mu must be in \[0, inf\).*got -0.5"):
        configure(path)


@pytest.mark.parametrize("name", ["bouncing_ball", "rigid_box", "flexible_cube"])
def test_mu_zero_by_default_builds_the_frictionless_contacts(name):
    """The default (mu = 0) gives contacts without friction rows (``mu=None``):
    the very model, hence the very trajectory, of the scene before friction."""
    scene = load_scene(name)
    assert scene.parameters["mu"] == 0.0
    assert scene.model.n_friction == 0
    assert all(getattr(c, "mu", None) is None for c in scene.model.contacts)
    assert load_scene(name, {"mu": 0.3}).model.n_friction > 0


def test_mu_zero_ball_is_the_point_mass_of_the_exact_solution():
    scene = load_scene("bouncing_ball", {"t_end": 1.0})
    assert scene.model.n_dof == 1
    sol = scene.run()
    exact = scene.exact(sol.ts)
    assert np.abs(sol.observables["z"] - exact["z"]).max() <= 2 * np.sqrt(2 * 9.81) * 1e-3


# ------------------------------------------------------------------ the ball

def _first_impact(sol):
    return int(np.nonzero(np.asarray(sol.observables["force"]) > 0)[0][0])


@pytest.mark.parametrize("spin, faster", [(30.0, False), (-30.0, True)])
def test_spin_turns_into_horizontal_velocity_at_the_impact(spin, faster):
    """A ball flying at vx = 1 m/s lands with backspin (ω > 0: its lowest point
    runs forward at vx + ω r = 4 m/s, friction pulls it back) or topspin
    (ω < 0: the lowest point runs backward, friction pushes it on)."""
    sol = load_scene("bouncing_ball", {"mu": 0.3, "vx": 1.0, "spin": spin, "t_end": 0.5}).run()
    o = sol.observables
    k = _first_impact(sol)
    assert o["vx"][k - 1] == pytest.approx(1.0, abs=1e-12)  # no friction in flight
    assert (o["vx"][k] > 1.0 + 0.1) == faster and (o["vx"][k] < 1.0 - 0.1) != faster
    # the impact kept the angular momentum about the contact point, J ω - m r vx
    J, r = 0.4 * 0.1**2, 0.1
    before, after = J * o["omega"][k - 1] - r * o["vx"][k - 1], J * o["omega"][k] - r * o["vx"][k]
    assert after == pytest.approx(before, abs=1e-10)
    # |friction impulse| <= mu * normal impulse
    assert abs(o["friction"][k]) <= 0.3 * o["force"][k] * (1 + 1e-9)
    energy_never_grows(sol)


def test_high_friction_ball_ends_rolling_without_slip():
    """With mu = 1 the contact sticks at the first impact: the ball rolls,
    vx = -ω r, at vx = (vx0 - (2/5) r ω0) / (7/5) (angular momentum about the
    contact point), and keeps rolling through the next bounces (e = 0.5)."""
    vx0, w0, r = 1.0, 30.0, 0.1
    sol = load_scene("bouncing_ball", {"mu": 1.0, "vx": vx0, "spin": w0, "e": 0.5, "t_end": 1.5}).run()
    o = sol.observables
    k = _first_impact(sol)
    rolling = (vx0 - 0.4 * r * w0) / 1.4
    assert np.abs(o["slip"][k:]).max() <= 1e-9
    assert np.abs(o["vx"][k:] - rolling).max() <= 1e-9
    assert np.abs(o["vx"][k:] + o["omega"][k:] * r).max() <= 1e-9
    assert sol.stats["failed_steps"] == 0
    energy_never_grows(sol)


# ------------------------------------------------------------------ incline

@pytest.mark.parametrize("overrides", [{}, {"velocity": -1.5}, {"mu": 0.4, "velocity": 1.0, "t_end": 1.5}],
                         ids=["slides-down", "sent-up-then-slides", "decelerates"])
def test_incline_follows_the_exact_sliding_law(overrides):
    """The velocity along the slope is exact to round-off while the block
    slides (the friction force is mu N each step), within one step's change
    g (sin + mu cos) h at the step where a block sent uphill turns back; so
    is s, but for the stopping or turning step (measured at h = 1e-3: 7e-16 m
    sliding down from rest, 3.9e-9 m decelerating to rest over 1.5 s, 5.3e-4 m
    sent up then sliding down, where the turn's step reverses the slip)."""
    scene = load_scene("incline", overrides)
    sol = scene.run()
    o, exact = sol.observables, scene.exact(sol.ts)
    p, h, t = scene.parameters, scene.solver["h"], scene.solver["t_end"]
    assert sol.stats["failed_steps"] == 0
    kick = p["gravity"] * (np.sin(p["angle"]) + p["mu"] * np.cos(p["angle"])) * h
    assert np.abs(o["ds"] - exact["ds"]).max() <= (kick if p["velocity"] < 0 else 1e-10)
    assert np.abs(o["s"] - exact["s"]).max() <= (p["gravity"] * h * t if p["velocity"] < 0 else
                                                  p["gravity"] * h**2)  # the stopping step's O(h²)
    assert np.abs(o["rotation"]).max() <= 1e-12  # flat on the slope: no corner lifts
    assert np.all(np.abs(o["friction"]) <= p["mu"] * p["mass"] * p["gravity"] * np.cos(p["angle"]) * (1 + 1e-9))
    energy_never_grows(sol)


def test_incline_block_at_rest_stays_at_rest_where_tan_angle_is_below_mu():
    """tan(0.3) = 0.309 <= mu = 0.4: the velocity stays zero to round-off and
    the friction force balances m g sin(angle), and the position does not
    creep (Coulomb's law in the position correction holds the contact points:
    measured 1.1e-17 m over 1 s)."""
    p = {"mu": 0.4}
    sol = load_scene("incline", p).run()
    o = sol.observables
    a, g = 0.3, 9.81
    assert np.abs(o["ds"]).max() <= 1e-12
    assert np.abs(o["friction"][1:] + g * np.sin(a)).max() <= 1e-9
    assert np.abs(o["s"]).max() <= 1e-14
    exact = incline(sol.ts, a, 0.4, g)
    assert np.all(exact[0] == 0.0) and np.all(exact[1] == 0.0)
    energy_never_grows(sol)


# ------------------------------------------------------------------ rocking block

def _impacts(theta):
    """Indices i with the impact in step i -> i + 1 (θ changes sign)."""
    return np.nonzero(np.sign(theta[1:]) != np.sign(theta[:-1]))[0]


def _housner_errors(h, t_end):
    """The run and, at each impact, |ω| at the end of the step that holds it over
    |ω| at its start, minus Housner's ratio, with one step's change of ω
    relative to ω there (gravity's work over the step)."""
    sol = load_scene("rocking_block", {"h": h, "t_end": t_end}).run()
    o = {k: np.asarray(v) for k, v in sol.observables.items()}
    omega, impacts = o["omega"], _impacts(o["theta"])
    errors = np.array([abs(omega[i + 1] / omega[i]) - housner_ratio(0.2, 0.6) for i in impacts])
    step_change = np.array([abs(omega[i] - omega[i - 1]) / abs(omega[i]) for i in impacts])
    return sol, o, impacts, errors, step_change


def test_rocking_block_follows_housners_ratio():
    """|ω+|/|ω-| at each of the first three impacts against 1 - (3/2) sin²α =
    0.85 (b = 0.2 m, h_b = 0.6 m): within one step's relative change of ω
    (measured at h = 1e-3 s: errors -5.2e-3, -6.4e-3, -8.0e-3 for step changes
    5.7e-3, 6.8e-3, 8.2e-3). The first impact's speed is the fall's from the
    tilt; the corners never slide while on the floor; the impacts dissipate."""
    sol, o, impacts, errors, step_change = _housner_errors(1e-3, 0.95)
    assert sol.stats["failed_steps"] == 0 and len(impacts) == 3
    assert housner_ratio(0.2, 0.6) == pytest.approx(0.85)
    assert np.all(np.abs(errors) <= step_change)
    first, _ = rocking_impacts(0.2, 0.6, 9.81, 0.15, 1)
    assert abs(o["omega"][impacts[0]]) == pytest.approx(first[0], rel=1e-2)  # measured 6.4e-3
    times = rocking_impact_times(0.2, 0.6, 9.81, 0.15, 3)
    assert abs(np.asarray(sol.ts)[impacts[0] + 1] - times[0]) < 1e-3  # within the step h (measured 4e-5 s)
    # later ones come early by the impacts' first-order loss (measured 6 ms and 14 ms at the 2nd and 3rd)
    assert np.all(np.abs(np.asarray(sol.ts)[impacts] - times) < 0.02)
    gaps = np.asarray(sol.gap)
    for k, name in enumerate(("slip_left", "slip_right")):
        touching = gaps[:, k] <= 1e-9
        assert touching.sum() > 0.2 * len(o["theta"])
        assert np.abs(o[name][touching]).max() <= 1e-9
    # impacts dissipate; between them the energy creeps up by the position correction's O(h) error on a
    # body turning about a sticking corner (measured 6.3e-5 relative from the first impact to the second)
    energy = np.asarray(o["energy"])
    assert np.all(energy[impacts + 1] < energy[impacts])
    between = energy[impacts[0] + 3:impacts[1] - 1]
    assert 0.0 <= between[-1] - between[0] <= 1e-4 * between[0]


def test_rocking_impact_times_follow_the_equation_of_motion():
    """The exact impact times (quadrature of the energy integral) against an
    RK4 integration (step 1e-4 s) of θ'' = -p² sin(α sgn θ - θ) with each
    crossing of θ = 0 found by bisection and Housner's jump there: equal to
    1e-9 s over four impacts."""
    b, hb, g, tilt = 0.2, 0.6, 9.81, 0.15
    alpha, p2, ratio = np.arctan2(b, hb), 3 * g / (2 * np.hypot(b, hb)), housner_ratio(b, hb)

    def rk4(y, dt, side):  # on the corner of ``side`` (+1 left, -1 right), continued past θ = 0
        def rhs(z):
            return np.array([z[1], -p2 * np.sin(alpha * side - z[0])])
        k1 = rhs(y)
        k2 = rhs(y + 0.5 * dt * k1)
        k3 = rhs(y + 0.5 * dt * k2)
        return y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + rhs(y + dt * k3))

    y, t, dt, crossings = np.array([tilt, 0.0]), 0.0, 1e-4, []
    while len(crossings) < 4:
        side = np.sign(y[0]) if y[0] != 0 else np.sign(y[1])
        nxt = rk4(y, dt, side)
        if np.sign(nxt[0]) == side:
            y, t = nxt, t + dt
            continue
        lo, hi = 0.0, dt  # the crossing, by bisection on the sub-step
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if np.sign(rk4(y, mid, side)[0]) == side else (lo, mid)
        t += hi
        crossings.append(t)
        y = np.array([0.0, ratio * rk4(y, hi, side)[1]])  # Housner's jump, onto the other corner
    np.testing.assert_allclose(rocking_impact_times(b, hb, g, tilt, 4), crossings, atol=1e-9)


@pytest.mark.slow
def test_housner_ratio_error_is_first_order_in_h():
    """Halving h halves the error of the measured ratio at the first four
    impacts (measured: 5.2e-3 -> 2.6e-3 at the first)."""
    coarse = _housner_errors(1e-3, 1.2)[3][:4]
    fine = _housner_errors(5e-4, 1.2)[3][:4]
    assert len(coarse) == len(fine) == 4
    assert np.all(np.abs(fine) <= 0.6 * np.abs(coarse))
    assert np.all(np.abs(fine) >= 0.4 * np.abs(coarse))


# ------------------------------------------------------------------ the box's impact

@pytest.mark.slow
def test_box_impact_follows_newtons_law_with_a_sticking_vertex():
    """The spinning box (mu = 0.5, e = 0.8) lands on vertex 5; the step's
    velocity against the exact impact law from the velocity before it:
    M (v+ - v-) = G_Bᵀ λ + w_N P_N + W_Tᵀ P_T with the rigidity kept
    (G_B v+ = 0), w_N v+ = -e w_N v- and a sticking vertex (W_T v+ = 0),
    |P_T| < mu P_N. The law raises the kinetic energy (Kane and Levinson's
    paradox: 2212.6 -> 2480.6 J) and DS follows it (2482.0 J, 5.4e-4 relative;
    its velocity within 2.4e-3 relative: the step also carries gravity and the
    spin, which turns the natural coordinates' velocities by ω h = 0.06 rad)."""
    scene = load_scene("rigid_box", {"mu": 0.5, "t_end": 0.417})
    with pytest.warns(nsga_jax.InvariantWarning, match="energy rose by .*Kane's paradox"):  # the gain is reported
        sol = scene.run()
    m, impulses = scene.model, np.asarray(sol.impulse)
    nb = m.n_bilateral
    k = int(np.nonzero(impulses[:, nb:].sum(axis=1) > 0)[0][0])
    vertex = int(np.argmax(impulses[k, nb:]))
    assert vertex == 5 and np.count_nonzero(impulses[k, nb:]) == 1
    q, before = np.asarray(sol.q[k]), np.asarray(sol.v[k - 1])
    M, GB = np.asarray(m.mass(q)), np.asarray(m.bilateral_jacobian(q))
    wN = np.asarray(m.constraint_jacobian(q))[nb + vertex]
    WT = np.asarray(m.tangent_jacobian(q))[2 * vertex:2 * vertex + 2]
    A = np.vstack([GB, wN, WT])
    n, r = M.shape[0], A.shape[0]
    x = np.linalg.solve(np.block([[M, -A.T], [A, np.zeros((r, r))]]),
                        np.concatenate([M @ before, np.zeros(nb), [-0.8 * wN @ before], [0.0, 0.0]]))
    exact, PN, PT = x[:n], x[n + nb], x[n + nb + 1:]
    assert PN > 0 and np.linalg.norm(PT) < 0.5 * PN  # sticking is admissible
    kinetic = lambda v: 0.5 * v @ M @ v  # noqa: E731
    assert kinetic(exact) > 1.1 * kinetic(before)  # the law itself gains energy
    after = np.asarray(sol.v[k])
    assert np.linalg.norm(after - exact) <= 5e-3 * np.linalg.norm(exact)
    assert kinetic(after) == pytest.approx(kinetic(exact), rel=2e-3)


def test_impacts_are_matched_one_to_one_while_resolvable():
    """:func:`match_impacts` on made-up runs against the rocking block's
    exact impacts: each shifted by a step, all matched; one missing and one
    doubled, both counted; a run that stops early leaves the rest unmatched."""
    exact = rocking_impact_times(0.2, 0.6, 9.81, 0.15, 400)
    h = 1e-3
    resolvable = resolvable_impacts(exact, h)
    assert len(resolvable) == 22 and np.all(np.diff(resolvable) >= 10 * h)
    assert exact[22] - exact[21] < 10 * h
    late = match_impacts(resolvable + h, exact, h)
    assert (late["matched"], late["extra"], late["resolvable"]) == (22, 0, 22)
    assert abs(late["max_error"] - h) < 1e-12
    doubled = np.sort(np.concatenate([resolvable[:-1], [resolvable[5] + 0.01]]))  # the last missing, one twice
    assert match_impacts(doubled, exact, h)["matched"] == 20
    assert match_impacts(doubled, exact, h)["extra"] == 2
    early = match_impacts(resolvable[:10], exact, h)
    assert (early["matched"], early["extra"]) == (10, 0)
    beyond = match_impacts(exact[:60], exact, h)  # the unresolvable ones after the last window are not counted
    assert (beyond["matched"], beyond["extra"]) == (22, 0)
