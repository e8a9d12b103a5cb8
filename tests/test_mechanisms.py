"""Mechanisms built from parts: the slider-crank with a flexible rod and a stop,
and the flexible appendage on a spinning hub.

Runs of one scene's structure and step count share one compiled program
(``integrate`` under ``eqx.filter_jit``, the model, the scheme, the initial
state and h as arguments)."""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import nsga_jax as nj
from nsga_jax._results import ConfigError
from nsga_jax.scenes import configure, load_scene

BILATERAL_TOL = 1e-8  # joints after every step: Newton tolerance (eq. 51) on metre-sized coordinates
PENETRATION_TOL = 1e-10


@eqx.filter_jit
def _run(model, scheme, q0, v0, h, n_steps):
    return nj.integrate(model, scheme, 0.0, n_steps * h, h, q0, v0, n_steps=n_steps, throw=False)


def run(name, overrides, h, n_steps, rho_inf=None):
    """The scene's observables and stats of a DS run of ``n_steps`` steps."""
    scene = load_scene(name, overrides)
    scheme = nj.DS(rho_inf=scene.solver["rho_inf"] if rho_inf is None else rho_inf)
    sol = _run(scene.model, scheme, scene.q0, scene.v0, jnp.asarray(h), n_steps)
    obs = {k: np.asarray(v) for k, v in scene.observables(sol).items()}
    stats = {k: np.asarray(v) for k, v in sol.stats.items() if k != "iterations"}
    return scene, obs, stats


def assert_clean(obs, stats):
    assert stats["failed_steps"] == 0
    assert stats["max_bilateral_violation_position"] <= BILATERAL_TOL
    assert stats["max_bilateral_violation_velocity"] <= BILATERAL_TOL
    assert np.all(obs["constraint"] <= BILATERAL_TOL)
    assert np.all(obs["gap"] >= -PENETRATION_TOL)


# ----------------------------------------------------------------- slider-crank


@pytest.fixture(scope="module")
def crank():
    """The default slider-crank (free crank, e = 0.8, gravity) over its first impact."""
    return run("slider_crank", {}, 1e-3, 100)


def test_slider_crank_joints_hold_and_the_stop_is_not_penetrated(crank):
    scene, obs, stats = crank
    assert_clean(obs, stats)
    assert np.all(obs["constraint_rate"] <= BILATERAL_TOL)
    assert obs["force"].max() > 0  # the slider struck the stop
    assert obs["slider_v"][-1] < 0 < obs["slider_v"][0]  # and came back
    assert np.abs(obs["rod_deflection"]).max() > 1e-4  # the impact bends the rod


def test_slider_crank_starts_on_the_rigid_mechanism_and_follows_it_before_the_impact(crank):
    """Before the impact the rod hardly deforms: the slider is where the rigid
    mechanism puts it, x = r cos θ + sqrt(L² - r² sin² θ), to the rod's axial
    strain."""
    scene, obs, _ = crank
    p = scene.parameters
    r, L = p["crank_length"], p["rod_length"]
    th = obs["crank_angle"]
    rigid = r * np.cos(th) + np.sqrt(L**2 - (r * np.sin(th)) ** 2)
    assert obs["slider_x"][0] == pytest.approx(rigid[0], abs=1e-14)
    before = np.arange(np.argmax(obs["force"] > 0))
    assert before.size > 20
    assert np.abs(obs["slider_x"][before] - rigid[before]).max() < 1e-5 * L


def test_slider_crank_energy_does_not_grow_through_impacts():
    """Torque-free, e ≤ 1: the energy (kinetic + strain + gravity) never rises
    above its initial value, and the inelastic stop dissipates."""
    for e in (1.0, 0.8):
        _, obs, stats = run("slider_crank", {"e": e}, 1e-3, 100)
        assert stats["failed_steps"] == 0 and obs["force"].max() > 0
        energy = obs["energy"]
        assert energy.max() <= energy[0] * (1 + 1e-9)
        if e < 1:
            assert energy[-1] < 0.9 * energy[0]


def test_free_slider_crank_without_stop_and_gravity_conserves_energy():
    """No stop, no gravity, no torque: the energy is conserved to the scheme's
    accuracy (ρ∞ = 1, second order: the drift falls with h)."""
    drifts = []
    for h in (2e-4, 1e-4):  # the same step count (one program); the drift over the first 0.03 s
        _, obs, stats = run("slider_crank", {"stop_x": 10.0, "gravity": 0.0}, h, 300, rho_inf=1.0)
        assert_clean(obs, stats)
        assert obs["force"].max() == 0
        energy = obs["energy"][:round(0.03 / h) + 1]
        drifts.append(np.abs(energy - energy[0]).max() / energy[0])
    assert drifts[1] < 1e-3
    assert drifts[1] < drifts[0]


def test_slider_crank_refuses_inconsistent_setups(no_compilation):
    with pytest.raises(ConfigError, match="rod_length"):
        configure("slider_crank", {"crank_length": 0.3, "rod_length": 0.2})
    with pytest.raises(ConfigError, match="stop"):
        configure("slider_crank", {"stop_x": 0.2})  # the slider starts at x = 0.26 m


def test_ds_converges_where_cs_fails_at_a_large_step():
    """h = 3e-3 s on the default slider-crank: DS converges through the impact
    with a few linear solves per step and holds every joint; CS diverges at
    the impact (t ≈ 0.042 s). At 1e-3 and 2e-3 s CS's coupled iteration
    wanders for up to 110 global iterations at the impact, and whether it
    lands within the cap of 200 depends on round-off (docs/mechanisms.md), so
    the test takes the smallest step of the study where CS's failure does not.
    The smooth motion's damped updates (docs/scheme.md, step 1) take up to
    32 Newton iterations in one step here (measured: 35 linear solves at
    most, 8.5 a step on average; with full updates 11 and 7.0)."""
    h = 3e-3
    ds = load_scene("slider_crank", {"h": h}).run(throw=False, progress=False)
    cs = load_scene("slider_crank", {"h": h, "scheme": "cs", "max_iter": 200}).run(throw=False, progress=False)
    assert ds.stats["failed_steps"] == 0
    assert ds.stats["max_bilateral_violation_position"] <= BILATERAL_TOL
    assert ds.stats["iterations"]["linear_solves"]["max"] <= 40
    assert ds.stats["iterations"]["linear_solves"]["mean"] <= 10
    assert cs.stats["failed_steps"] > 0
    first = float(cs.ts[cs.failed_steps[0]])
    impact = float(ds.ts[np.argmax(np.asarray(ds.observables["force"]) > 0)])
    assert abs(first - impact) <= h


# ---------------------------------------------------------- flexible appendage


@pytest.fixture(scope="module")
def appendage():
    return run("flexible_appendage", {}, 1e-3, 400, rho_inf=0.5)  # through the first impacts (t = 0.26 s)


def test_appendage_tip_stays_admissible_and_the_clamp_holds(appendage):
    scene, obs, stats = appendage
    assert_clean(obs, stats)
    assert obs["force"].max() > 0  # the tip struck the stop
    assert obs["tip_deflection"].min() < -0.05  # and the beam bent behind the hub
    assert obs["hub_omega"][-1] < 0  # which the beam turned back


def test_appendage_energy_does_not_grow(appendage):
    _, obs, _ = appendage
    energy = obs["energy"]
    assert energy.max() <= energy[0] * (1 + 1e-9)
    assert energy[-1] < energy[0]  # e = 0.5


def test_appendage_starts_as_a_rigid_rotation(appendage):
    scene, obs, _ = appendage
    p = scene.parameters
    assert obs["tip_deflection"][0] == 0.0
    assert obs["tip_x"][0] == pytest.approx(p["hub_radius"] + p["length"], abs=1e-14)
    # before the tip reaches the stop, the spinning beam stays close to its rigid line
    before = np.arange(np.argmax(obs["force"] > 0))
    assert before.size > 50
    assert np.abs(obs["tip_deflection"][before]).max() < 1e-3 * p["length"]
    omega = obs["hub_omega"][before]
    assert np.abs(omega - p["hub_omega"]).max() < 1e-2 * p["hub_omega"]
    assert math.isclose(float(obs["hub_angle"][0]), p["angle"])


def test_appendage_refuses_a_tip_above_the_stop(no_compilation):
    with pytest.raises(ConfigError, match="stop"):
        configure("flexible_appendage", {"stop_y": 0.5, "angle": 1.0})


def test_variants_build_consistently():
    """The torque-driven crank and the free hub: the joints hold at the start,
    and the drive is the configured moment on the crank's angle."""
    crank = load_scene("slider_crank", {"drive": "torque", "torque": 0.5})
    model = crank.model
    f = np.asarray(model.force(jnp.asarray(crank.q0), jnp.zeros_like(jnp.asarray(crank.v0)), 0.0))
    assert f[model.coordinates("crank")][2] == pytest.approx(0.5)
    assert not model.has_energy  # a prescribed load has no potential; the scene's energy adds -τ (θ - θ0)
    free = load_scene("flexible_appendage", {"hub": "free"})
    assert free.model.joint_names == ("clamp",) and free.model.n_bilateral == 3
    assert np.abs(np.asarray(free.model.bilateral(jnp.asarray(free.q0)))).max() < 1e-12
