"""The fast subset of configs/extreme/ (experiments/studies/stability.py runs them all,
with every scheme): invariants that must hold on elastic, plastic, resting,
simultaneous, stiff and tiny- or huge-step cases."""

from pathlib import Path

import numpy as np
import pytest

from nsga_jax.scenes import load_scene

EXTREME = Path(__file__).resolve().parents[1] / "nsga_jax" / "configs" / "extreme"
G = 9.81


def run(name, **overrides):
    sol = load_scene(EXTREME / f"{name}.toml", overrides).run(progress=False)
    assert sol.stats["failed_steps"] == 0
    return sol


def apexes(z):
    i = np.nonzero((z[1:-1] >= z[:-2]) & (z[1:-1] > z[2:]))[0] + 1
    return z[i]


def test_every_extreme_config_loads():
    names = sorted(p.stem for p in EXTREME.glob("*.toml"))
    assert len(names) >= 15
    for name in names:
        load_scene(EXTREME / f"{name}.toml")


def test_elastic_ball_energy_never_grows_and_height_loss_is_first_order():
    # 100 impacts. DS applies the impact law with the velocity at the start of the impact
    # step, so a bounce loses the speed gravity adds between the start of the step and the
    # impact: at most g h, g h / 2 on average when the impacts fall anywhere in their steps
    # (thrown up at 0.3 m/s so that they do; dropped from rest, every flight ends exactly on
    # a step and round-off decides between losing nothing and losing g h). Energy never grows.
    for velocity in (0.3, 0.0):
        sol = run("ball_elastic", t_end=91.0, velocity=velocity)
        energy = np.asarray(sol.observables["energy"])
        assert energy.max() <= energy[0] * (1 + 1e-12)
        assert sol.stats["max_penetration"] < 1e-10
        a = apexes(np.asarray(sol.observables["z"]))
        assert len(a) >= 100
        speed_loss = np.sqrt(2 * G * a[:-1]) - np.sqrt(2 * G * a[1:])
        h = sol.stats["h"]
        assert np.all(speed_loss <= G * h * (1 + 1e-6)) and np.all(speed_loss >= -1e-9)
        if velocity:
            assert 0.35 * G * h < speed_loss.mean() < 0.65 * G * h


def test_elastic_ball_with_moreau_jean_keeps_its_height():
    sol = run("ball_elastic", t_end=91.0, scheme="mj")
    a = apexes(np.asarray(sol.observables["z"]))
    assert len(a) >= 99
    np.testing.assert_allclose(a, 1.0, atol=1e-9)


@pytest.mark.parametrize("scheme", ["ds", "dsn"])
def test_ball_comes_to_rest_through_the_accumulation_point(scheme):
    # e = 0.5 from 1 m: the impacts accumulate at t = 1.35 s
    sol = run("ball_zeno_e05", scheme=scheme)
    rest = sol.ts > 1.5
    z, v, f = (np.asarray(sol.observables[k]) for k in ("z", "vz", "force"))
    assert sol.stats["max_penetration"] == 0.0
    np.testing.assert_array_equal(z[rest], 0.0)  # no jitter
    assert np.abs(v[rest]).max() < 1e-12
    np.testing.assert_allclose(f[rest], G, rtol=1e-12)  # m g, m = 1 kg


def test_plastic_ball_stops_at_the_first_impact():
    sol = run("ball_zeno_e0")
    z = np.asarray(sol.observables["z"])
    first = np.nonzero(z == 0.0)[0][0]
    assert abs(sol.ts[first] - np.sqrt(2 / G)) <= 1e-3
    np.testing.assert_array_equal(z[first:], 0.0)


def test_resting_contact_from_the_start():
    sol = run("ball_resting")
    np.testing.assert_array_equal(np.asarray(sol.observables["z"]), 0.0)
    np.testing.assert_array_equal(np.asarray(sol.observables["vz"]), 0.0)
    np.testing.assert_allclose(np.asarray(sol.observables["force"])[1:], G, rtol=1e-12)


def test_box_dropped_flat_lands_on_four_vertices_at_once():
    # Four coplanar contacts on a rigid body are redundant: the impulses that stop it are
    # not unique (the solve may put them on one vertex), the motion is.
    sol = run("box_flat", t_end=0.6)
    gaps = np.asarray(sol.gap)
    lower = np.argsort(gaps[0])[:4]
    assert np.abs(gaps[:, lower] - gaps[:, lower[:1]]).max() < 1e-12  # they stay level
    assert np.asarray(sol.impulse)[:, lower].sum() > 0
    assert sol.stats["max_penetration"] < 1e-12
    for k in ("omega_x", "omega_y", "omega_z"):  # no spurious spin
        assert np.abs(np.asarray(sol.observables[k])).max() < 1e-9
    vz = np.asarray(sol.observables["vz"])
    assert vz.max() > 0.4 * np.sqrt(2 * G * 0.5)  # it rebounds (e = 0.5)


def test_stiff_bar_at_a_large_step():
    # E x 1e3: the wave crosses 1900 elements per step
    sol = run("bar_stiff_1e3")
    assert sol.stats["max_penetration"] < 1e-10
    energy = np.asarray(sol.observables["energy"])
    assert energy.max() <= energy[0] * (1 + 1e-7)  # measured: 1.0e-8 before the impact
    assert sol.stats["iterations"]["linear_solves"]["max"] <= 3


@pytest.mark.parametrize("h, t_end", [(1e-6, 0.5), (0.1, 3.0)])
def test_ball_at_extreme_steps(h, t_end):
    sol = run("ball_h_1e-1", h=h, t_end=t_end)
    assert sol.stats["max_penetration"] < 1e-12
    z = np.asarray(sol.observables["z"])
    first = np.nonzero(np.asarray(sol.impulse)[:, 0] > 0)[0]
    if h < 0.01:
        assert abs(sol.ts[first[0]] - np.sqrt(2 / G)) <= 2 * h
    assert z.max() <= 1.0 + 1e-12


@pytest.mark.parametrize("scheme", ["cs", "mj"])
def test_redundant_contacts_with_the_other_schemes(scheme):
    # the flat landing makes the Delassus block singular: a relative shift of 1e-12 keeps the
    # solve finite (before it, CS diverged and MJ produced a non-finite velocity here)
    sol = run("box_flat", t_end=0.4, scheme=scheme)
    assert np.asarray(sol.impulse).sum() > 0
    assert np.isfinite(np.asarray(sol.v)).all()
