"""The worked example of a user model and scene (nsga_jax/examples/double_pendulum.py):
its physics against an independent reference in angle coordinates, and every
command of the command line on it."""

import csv
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

import nsga_jax
from nsga_jax.scenes import load_scene

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = "examples/double_pendulum.py"  # as the docs write it: read from the package, from any folder


def scene(overrides=None):
    return load_scene(EXAMPLE, overrides)


# ----------------------------------------------------- the reference solution


def _angle_rhs(t, y, args):
    """The double pendulum's Lagrange equations in the angles θ1, θ2 from the
    downward vertical; y = [θ1, θ2, θ1', θ2'], args = [m1, m2, l1, l2, g, wall_x, side]."""
    import jax.numpy as jnp

    m1, m2, l1, l2, g = args[0], args[1], args[2], args[3], args[4]
    th1, th2, w1, w2 = y
    d = th1 - th2
    A = jnp.array([[(m1 + m2) * l1, m2 * l2 * jnp.cos(d)], [l1 * jnp.cos(d), l2]])
    b = jnp.stack([-m2 * l2 * jnp.sin(d) * w2**2 - (m1 + m2) * g * jnp.sin(th1),
                   l1 * jnp.sin(d) * w1**2 - g * jnp.sin(th2)])
    acc = jnp.linalg.solve(A, b)
    return jnp.stack([w1, w2, acc[0], acc[1]])


def _wall_gap(t, y, args, **kwargs):
    """side (x2 - wall_x) [m] in the angles."""
    import jax.numpy as jnp

    l1, l2, wall_x, side = args[2], args[3], args[5], args[6]
    return side * (l1 * jnp.sin(y[0]) + l2 * jnp.sin(y[1]) - wall_x)


def _impact_map(p, th1, th2, w):
    """Newton's law on the wall's normal velocity J θ' (J = dx2/dθ) with the
    rods rigid: Mθ (θ'⁺ - θ'⁻) = Jᵀ Λ, J θ'⁺ = -e J θ'⁻. Returns θ'⁺, the
    normal velocities before and after [m/s] and the kinetic energy lost [J]."""
    m1, m2, l1, l2, e = (p[k] for k in ("m1", "m2", "l1", "l2", "e"))
    c = m2 * l1 * l2 * math.cos(th1 - th2)
    mass = np.array([[(m1 + m2) * l1**2, c], [c, m2 * l2**2]])
    J = np.array([l1 * math.cos(th1), l2 * math.cos(th2)])
    minv_j = np.linalg.solve(mass, J)
    before = float(J @ w)
    impulse = -(1.0 + e) * before / float(J @ minv_j)
    after_w = w + impulse * minv_j
    lost = 0.5 * (1.0 - e**2) * before**2 / float(J @ minv_j)
    return after_w, before, float(J @ after_w), lost


def reference(ts, p, side):
    """Event-driven reference of the scene with parameters ``p``: the angle
    equations between impacts (diffrax, Dopri8, tolerances 1e-12), the impact
    instants by root finding on the gap, Newton's law at each (:func:`_impact_map`).

    Returns ``(x2, vx2, impacts)``: x2 [m] and vx2 [m/s] at the times ``ts``,
    and a list of (instant [s], normal velocity before, after [m/s], kinetic
    energy lost [J]) per impact.
    """
    import diffrax
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    ts = np.asarray(ts, float)
    args = jnp.array([p["m1"], p["m2"], p["l1"], p["l2"], p["gravity"], p["wall_x"], side])
    term = diffrax.ODETerm(_angle_rhs)
    event = diffrax.Event(_wall_gap, root_finder=optx.Newton(rtol=1e-12, atol=1e-13))
    controller = diffrax.PIDController(rtol=1e-12, atol=1e-12)
    y = np.empty((ts.size, 4))
    t0, y0, t_end, impacts = 0.0, jnp.array([p["theta1"], p["theta2"], p["omega1"], p["omega2"]]), ts[-1], []
    while True:
        sol = diffrax.diffeqsolve(term, diffrax.Dopri8(), t0, t_end, 1e-3, y0, args=args, event=event,
                                  saveat=diffrax.SaveAt(dense=True, t1=True), stepsize_controller=controller,
                                  max_steps=100_000)
        t1 = float(sol.ts[-1])
        inside = (ts >= t0) & (ts <= t1)
        y[inside] = np.asarray(jax.vmap(sol.evaluate)(jnp.clip(jnp.asarray(ts), t0, t1)))[inside]
        if t1 >= t_end or not sol.event_mask:
            break
        th1, th2, w1, w2 = np.asarray(sol.ys[-1])
        after, before, after_normal, lost = _impact_map(p, th1, th2, np.array([w1, w2]))
        impacts.append((t1, before, after_normal, lost))
        # leave the wall by an Euler step of 1 ns (error ~1e-17 m) so that the
        # next segment does not start on the event surface
        y1 = jnp.array([th1, th2, after[0], after[1]])
        t0, y0 = t1 + 1e-9, y1 + 1e-9 * _angle_rhs(t1, y1, args)
    th1, th2, w1, w2 = y.T
    x2 = p["l1"] * np.sin(th1) + p["l2"] * np.sin(th2)
    vx2 = p["l1"] * np.cos(th1) * w1 + p["l2"] * np.cos(th2) * w2
    return x2, vx2, impacts


# ------------------------------------------------------------ the scene file


def test_scene_file_registers_and_refuses_bad_setups():
    s = scene()
    assert s.name == "double_pendulum_masses" and type(s.model).__name__ == "DoublePendulum"
    assert s.spec.observables[0] == "x2" and s.spec.error_observables == ("x2", "vx2")
    # q0 on both rods, v0 along them (the initial state is consistent)
    assert np.abs(s.model.bilateral(s.q0)).max() < 1e-15
    G = np.asarray(s.model.constraint_jacobian(s.q0))
    assert np.abs(G[:2] @ s.v0).max() < 1e-14
    assert float(s.model.unilateral(s.q0)[0]) > 0
    # the same scene by name in the file, and from the TOML config beside it
    assert load_scene(f"{EXAMPLE}:double_pendulum_masses").name == "double_pendulum_masses"
    config = load_scene(ROOT / "nsga_jax/examples/double_pendulum.toml")
    assert config.name == "double_pendulum_masses" and config.parameters["e"] == 0.5 and config.solver["h"] == 5e-4
    with pytest.raises(nsga_jax.ConfigError, match="wall_x"):
        scene({"wall_x": -0.3})  # the upper mass could reach it
    with pytest.raises(nsga_jax.ConfigError, match="theta1, theta2: the lower mass starts beyond the wall"):
        scene({"wall_x": 0.6})
    with pytest.raises(nsga_jax.ConfigError, match="starts on the wall"):
        scene({"wall_x": -0.5, "theta1": -math.pi / 2, "theta2": 0.0})
    with pytest.raises(nsga_jax.ConfigError, match="e must be in"):
        scene({"e": 1.5})


# ------------------------------------------------------- smooth motion: no wall


@pytest.fixture(scope="module")
def free_runs():
    """The pendulum with the wall out of reach, at two step sizes, and its reference."""
    runs = {}
    for h in (4e-3, 2e-3):
        s = scene({"wall_x": 100.0, "h": h, "t_end": 1.0})
        sol = s.run(progress=False)
        x2, vx2, impacts = reference(sol.ts, s.parameters, float(s.model.side))
        assert not impacts
        runs[h] = (s, sol, x2, vx2)
    return runs


def test_smooth_motion_matches_the_angle_equations_to_second_order(free_runs):
    errors = {}
    for h, (s, sol, x2, vx2) in free_runs.items():
        assert sol.stats["failed_steps"] == 0 and not np.any(sol.impulse[:, 2])
        errors[h] = np.abs(sol.observables["x2"] - x2).max()
        # generalized-α is second order in smooth motion: |error| <= C h², C = 50 m/s²
        assert errors[h] < 50.0 * h**2, (h, errors[h])
        assert np.abs(sol.observables["vx2"] - vx2).max() < 500.0 * h**2
    assert errors[4e-3] / errors[2e-3] > 3.0  # halving h divides it by about 4


def test_rods_hold_at_position_and_velocity_level(free_runs):
    for s, sol, _, _ in free_runs.values():
        assert np.abs(sol.records.bilateral).max() < 1e-8        # g^B(q_{n+1}) [m]
        assert np.abs(sol.records.bilateral_rate).max() < 1e-8   # g_q^B v_{n+1} [m/s]
        assert np.abs(sol.observables["rod1"]).max() < 1e-8
        assert np.abs(sol.observables["rod2"]).max() < 1e-8
        # no impact: the energy is kept to second order (generalized-α is not
        # energy-monotone with nonlinear constraints; it dissipates O(h²) per unit time)
        energy = sol.observables["energy"]
        assert np.abs(energy - energy[0]).max() < 200.0 * sol.h**2  # [J]; about 116 h² seen


# ------------------------------------------------------------ impacts: the wall


@pytest.fixture(scope="module")
def wall_run():
    """The default scene: mass 2 strikes the wall twice in 2 s."""
    s = scene({"h": 1e-3})
    sol = s.run(progress=False)
    impacts = np.nonzero(sol.impulse[:, 2] > 0)[0]
    assert sol.stats["failed_steps"] == 0 and len(impacts) >= 2
    return s, sol, impacts


def test_no_penetration_and_rods_hold_through_impacts(wall_run):
    s, sol, impacts = wall_run
    assert sol.gap.min() > -1e-8 and sol.observables["gap"].min() > -1e-8
    assert np.abs(sol.records.bilateral).max() < 1e-8
    assert np.abs(sol.records.bilateral_rate).max() < 1e-8
    force = sol.observables["force"]
    assert force.min() >= 0.0 and np.all(force[impacts] > 100.0)  # the wall pushes, hard, at impacts only
    assert np.all(sol.observables["gap"][impacts] < 1e-8)


def test_energy_never_increases_at_an_impact(wall_run):
    s, sol, impacts = wall_run
    energy = sol.observables["energy"]
    np.testing.assert_allclose(energy, jax.vmap(s.model.energy)(sol.q, sol.v), rtol=1e-12, atol=1e-12)
    assert energy.max() <= energy[0] + 200.0 * sol.h**2  # smooth phases: second-order drift at most
    for k in impacts:
        assert energy[k] < energy[k - 1], k


def test_newton_law_at_the_wall(wall_run):
    s, sol, impacts = wall_run
    e, side = s.parameters["e"], float(s.model.side)
    for k in impacts:
        before, after = side * sol.v[k - 1, 2], side * sol.v[k, 2]
        assert before < 0  # approaching
        # the velocity problem imposes g_q v_{n+1} = -e g_q v_n on the active contact (eq. 32a)
        assert after == pytest.approx(-e * before, rel=1e-8, abs=1e-10)


def test_impact_against_event_driven_reference(wall_run):
    """Impact instant, normal velocities, energy lost and the motion after the
    impact agree with the event-driven reference to first order in h."""
    s, sol, impacts = wall_run
    p, h, side = s.parameters, sol.h, float(s.model.side)
    window = sol.ts <= 0.6  # one impact; the chaotic motion later magnifies the O(h) shift
    x2, vx2, ref_impacts = reference(sol.ts[window], p, side)
    assert len(ref_impacts) == 1
    t_star, before, after, lost = ref_impacts[0]
    k = impacts[0]
    speed = np.abs(sol.v[:, 2:]).max()  # largest velocity component of mass 2 [m/s]
    acceleration = np.abs(np.diff(sol.v[:, 2:], axis=0)) / h
    acceleration = np.delete(acceleration, impacts - 1, axis=0).max()  # between impacts [m/s²]
    assert sol.ts[k - 1] < t_star <= sol.ts[k] + 1e-12  # the impulse falls in the step that holds t*
    # the scheme's normal velocities at t_{k-1} and t_k are the reference's at t*, a time < h away
    assert abs(side * sol.v[k - 1, 2] - side * before) < 2.0 * acceleration * h
    assert abs(side * sol.v[k, 2] - side * after) < 2.0 * acceleration * h
    energy = sol.observables["energy"]
    assert energy[k - 1] - energy[k] == pytest.approx(lost, rel=0.02)  # ½ (1 - e²) m_eff v⁻², through the rods
    err = np.abs(sol.observables["x2"][window] - x2)
    assert err[sol.ts[window] < t_star].max() < 50.0 * h**2  # before: smooth, second order
    # after: the impact placed at the end of its step shifts the motion by less than h
    assert err.max() < 2.0 * speed * h
    assert np.abs(sol.observables["vx2"][window] - vx2).max() < 2.0 * acceleration * h


# --------------------------------------------------------- the command line


COMMANDS = {
    "run": ["run", EXAMPLE, "--t-end", "0.5", "--quiet"],
    "sweep": ["sweep", EXAMPLE, "--grid", "e=0.2;0.8", "--set", "t_end=0.5", "--quiet"],
    "convergence": ["convergence", EXAMPLE, "--h", "4e-3,2e-3", "--ref-h", "5e-4", "--set", "t_end=0.4"],
    "identify": ["identify", EXAMPLE, "--params", "e", "--synthetic", "--true", "e=0.5", "--initial", "e=0.6",
                 "--set", "t_end=0.45", "--h", "4e-3", "--max-steps", "10"],
}
"""Each command on the scene file, with a t_end past the first impact (t ≈ 0.32 s)."""


@pytest.fixture(scope="module")
def cli(tmp_path_factory):
    """Start the four commands at once (each compiles its programs; they share
    the machine's cores), from a folder that holds no copy of the example;
    ``cli(name)`` waits for one and returns its output folder."""
    base = tmp_path_factory.mktemp("own_model_cli")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    procs = {}
    for name, args in COMMANDS.items():
        out = base / name
        log = open(base / f"{name}.log", "w")
        procs[name] = (subprocess.Popen([sys.executable, "-m", "nsga_jax._cli", *args, "--out", str(out)], cwd=base,
                                        env=env, stdout=log, stderr=subprocess.STDOUT), out, log)

    def wait(name):
        proc, out, log = procs[name]
        rc = proc.wait(timeout=600)
        log.flush()
        assert rc == 0, (base / f"{name}.log").read_text()[-3000:]
        return out

    yield wait
    for proc, _, log in procs.values():
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        log.close()


def test_cli_run(cli):
    out = cli("run")
    for name in ("trajectory.npz", "summary.json", "observables.png", "iterations.png"):
        assert (out / name).stat().st_size > 1000, name
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scene"] == "double_pendulum_masses" and summary["n_steps"] == 500
    assert summary["failed_steps"] == 0 and summary["max_penetration"] < 1e-8
    assert summary["max_bilateral_violation_position"] < 1e-8
    data = np.load(out / "trajectory.npz")
    assert data["q"].shape == (501, 4)
    assert data["force"].max() > 100.0 and data["gap"].min() > -1e-8  # the impact at t ≈ 0.32 s is in


def test_cli_sweep(cli):
    out = cli("sweep")
    with open(out / "sweep.csv") as f:
        rows = list(csv.DictReader(f))
    assert [float(r["e"]) for r in rows] == [0.2, 0.8]
    for r in rows:
        assert r["result"] == "successful" and float(r["max_penetration"]) < 1e-8
    # a softer wall keeps less energy
    assert float(rows[0]["energy_final"]) < float(rows[1]["energy_final"]) < float(rows[1]["energy_max"])


def test_cli_convergence(cli):
    out = cli("convergence")
    with open(out / "study.csv") as f:
        rows = list(csv.DictReader(f))
    assert [float(r["h"]) for r in rows] == [4e-3, 2e-3]
    for r in rows:
        assert int(r["failed_steps"]) == 0
        assert 0.0 < float(r["error_x2"]) < 0.05 and 0.0 < float(r["error_vx2"]) < 0.05
    assert float(rows[1]["error_x2"]) < float(rows[0]["error_x2"])
    assert (out / "convergence.png").exists()


def test_cli_identify_recovers_restitution(cli):
    out = cli("identify")
    result = json.loads((out / "identification.json").read_text())
    assert result["true"] == {"e": 0.5} and result["initial"]["e"] == pytest.approx(0.6)
    assert result["relative_error"]["e"] < 0.03, result
    assert (out / "fit.png").exists() and (out / "data.csv").exists()
