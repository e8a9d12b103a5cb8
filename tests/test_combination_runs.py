"""Feature combinations of forward runs and drivers that no other test checks
(docs' survey of combinations, "Gaps"): each scheme on each kind of model
against the reference DS is checked against, ``integrate`` against
``simulate``, batches and sweeps against single runs, float32 against
float64, identification, the command line, and refusals, on the rigid,
friction, matrix-free and system-file models.

Tolerances follow each scheme's order: DS, DSn and CS are second order while
the motion is smooth (generalized-α) and first order through an impact (its
instant is known to within a step); Moreau–Jean (MJ, θ = 1/2 on the
velocity, contacts activated from the predicted position) is first order
everywhere. Each bound states what was seen."""

from __future__ import annotations

import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from reference_models import BouncingBall
from scipy.integrate import solve_ivp
from test_integrate import assert_same_run
from test_rigid_box import euler_reference

import nsga_jax as nj
from nsga_jax import _memory as memory
from nsga_jax._batch import stack_models
from nsga_jax._cli import main
from nsga_jax._exact_pendulums import double_pendulum
from nsga_jax._identify import Data, identify, synthetic_data
from nsga_jax._metrics import observed_order, relative_l1_error
from nsga_jax._sweep import sweep
from nsga_jax.scenes import load_scene, parametrize

SYSTEMS = Path(__file__).resolve().parents[1] / "nsga_jax" / "configs" / "systems"
BALL_FILE = str(SYSTEMS / "ball_between_walls.toml")
BLOCK_FILE = str(SYSTEMS / "sliding_block.toml")
INCLINE = {"t_end": 0.3}  # mu = 0.2 < tan 0.3: the block slides (exact solution known) from the first step


pytestmark = pytest.mark.usefixtures("scene_registry")  # system files register scenes (conftest)


def quiet_run(scene, **kwargs):
    """A run whose invariant warnings are expected (MJ holds its constraints at
    velocity level only, so its joints drift and its gaps open late: named
    warnings, not failures)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", nj.InvariantWarning)
        return scene.run(progress=False, **kwargs)


def assert_same_values(a, b, scale_q=1.0, scale_v=1.0, rtol=1e-12):
    """Two runs of one problem by different drivers: same steps, the same
    states and impulses to round-off of their sizes, the same Newton counts."""
    assert a.n_steps == b.n_steps
    np.testing.assert_allclose(a.ts, b.ts, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=rtol * max(1.0, scale_q))
    np.testing.assert_allclose(a.v, b.v, rtol=0, atol=rtol * 1e2 * max(1.0, scale_v))
    np.testing.assert_allclose(a.impulse, b.impulse, rtol=0, atol=1e-10 * max(1.0, np.abs(b.impulse).max()))
    np.testing.assert_array_equal(a.iterations, b.iterations)


# =============================================================== forward runs


@pytest.mark.slow
def test_ball_with_cs_converges_to_the_exact_solution():
    """CS on the point mass against the exact solution, eq. 52: first order
    through the impacts, as DS (test_bouncing_ball::test_first_order_convergence_of_position)."""
    hs = [4e-3, 2e-3, 1e-3]
    errors = []
    for h in hs:
        scene = load_scene("bouncing_ball", {"h": h, "t_end": 1.5, "scheme": "cs"})
        sol = scene.run()
        assert sol.stats["failed_steps"] == 0
        exact = scene.exact(sol.ts)
        errors.append({k: relative_l1_error(sol.observables[k], exact[k]) for k in scene.spec.error_observables})
    order_z = observed_order(hs, [e["z"] for e in errors])
    assert 0.8 <= order_z <= 1.5, errors  # seen 1.25
    assert errors[-1]["z"] < 3e-3  # seen 2.1e-3, DS's bound at h = 5e-4 is 2e-3
    assert observed_order(hs, [e["vz"] for e in errors]) >= 0.8  # seen 2.2
    assert errors[-1]["vz"] < 2e-3  # seen 1.1e-3


def pendulum_reference(ts, length, gravity, angle, wall_x, e):
    """The rigid pendulum event-driven: θ'' = -(g/l) sin θ between impacts
    (DOP853, 1e-12), ω -> -e ω where the bob reaches the wall (x = l sin θ = wall_x)."""
    th_wall = np.arcsin(wall_x / length)

    def hit(t, y):
        return y[0] - th_wall

    hit.terminal, hit.direction = True, -np.sign(angle - th_wall)
    out, t0, y0, impacts = np.empty((len(ts), 2)), 0.0, [angle, 0.0], []
    while True:
        r = solve_ivp(lambda t, y: [y[1], -gravity / length * np.sin(y[0])], (t0, ts[-1] + 1e-9), y0, events=hit,
                      rtol=1e-12, atol=1e-12, dense_output=True, method="DOP853")
        t_end = r.t_events[0][0] if r.t_events[0].size else np.inf
        inside = (ts >= t0) & (ts < t_end)
        out[inside] = r.sol(ts[inside]).T
        if not np.isfinite(t_end):
            return out, impacts
        impacts.append(t_end)
        t0, y0 = t_end, [th_wall, -e * r.y_events[0][0][1]]


@pytest.mark.slow
@pytest.mark.parametrize("scheme", ["dsn", "cs", "mj"])
def test_rigid_pendulum_follows_the_event_driven_reference(scheme):
    """The bob's x and vx against the event-driven pendulum through its first
    wall impact (t* = 0.638 s), at two steps. Before the impact: second order
    for DSn and CS (seen 1.4 h² in x, 2.9 h² in vx, as DS), first order for MJ
    (seen 1.6 h, 6.1 h). After it (3 steps past t*, where every scheme has
    seen the impact): first order, the impact being placed at the end of its
    step (seen 2.2 h and 5.4 h; MJ 7.1 h and 17 h)."""
    second = scheme != "mj"
    pre_err = {}
    for h in (2e-3, 1e-3):
        scene = load_scene("rigid_pendulum", {"h": h, "t_end": 1.5, "scheme": scheme})
        sol = quiet_run(scene)
        assert sol.stats["failed_steps"] == 0
        p = scene.parameters
        ref, impacts = pendulum_reference(sol.ts, p["length"], p["gravity"], p["angle"], p["wall_x"], p["e"])
        assert len(impacts) == 1 and abs(impacts[0] - 0.638) < 1e-3
        x, vx = p["length"] * np.sin(ref[:, 0]), p["length"] * np.cos(ref[:, 0]) * ref[:, 1]
        pre, post = sol.ts < impacts[0], sol.ts > impacts[0] + 3 * h
        ex, ev = np.abs(sol.observables["x"] - x), np.abs(sol.observables["vx"] - vx)
        bound = (3 * h**2, 6 * h**2) if second else (3 * h, 12 * h)
        assert ex[pre].max() < bound[0] and ev[pre].max() < bound[1], (h, ex[pre].max(), ev[pre].max())
        post_bound = (5 * h, 10 * h) if second else (15 * h, 30 * h)
        assert ex[post].max() < post_bound[0] and ev[post].max() < post_bound[1], (h, ex[post].max(), ev[post].max())
        pre_err[h] = ex[pre].max()
    ratio = pre_err[2e-3] / pre_err[1e-3]
    assert (3.0 < ratio < 5.0) if second else (1.6 < ratio < 2.5), ratio  # 4 or 2; seen 4.0 and 2.0


@pytest.mark.slow
@pytest.mark.parametrize("scheme", ["dsn", "cs", "mj"])
def test_rigid_box_flight_follows_the_rigid_body_ode(scheme):
    """The spinning box's flight (t < 0.1 s, long before its first impact at
    0.42 s) against the Newton–Euler ODE, as DS in
    test_rigid_box::test_flight_before_impact_matches_rigid_body_ode. The
    centre falls freely, exactly for every scheme (seen 1e-14 m). The rotation
    matrix: second order for DSn and CS (seen 6.7e3 h²: nothing nonsmooth acts
    in flight, so DSn's dropped terms vanish); first order for MJ (seen 1.2e3
    h, large: the box spins at 60 rad/s and MJ holds the rigidity
    constraints at velocity level only, so they drift)."""
    errors = {}
    for h in (4e-4, 2e-4):
        scene = load_scene("rigid_box", {"h": h, "t_end": 0.1, "scheme": scheme})
        sol = quiet_run(scene)
        assert np.all(sol.impulse[:, 6:] == 0.0) and sol.stats["failed_steps"] == 0  # no contact yet
        every = int(round(2e-3 / h))
        r_ref, R_ref = euler_reference(scene, sol.ts[::every])
        np.testing.assert_allclose(sol.q[::every, :3], r_ref, atol=1e-10)
        errors[h] = np.abs(sol.observables["rotation"][::every] - R_ref).max()
    order = np.log2(errors[4e-4] / errors[2e-4])
    if scheme == "mj":
        assert errors[2e-4] < 0.3 and order == pytest.approx(1.0, abs=0.3), errors  # seen 0.24, 0.92
    else:
        assert errors[2e-4] < 4e-4 and order == pytest.approx(2.0, abs=0.3), errors  # seen 2.7e-4, 1.99


@pytest.mark.slow
def test_bar_with_dsn_follows_the_exact_wave_solution():
    """DSn on the impacting bar (paper §4.2) against the exact wave solution
    (test_impacting_bar's references). DSn drops f^p, the O(h²) position
    correction of the contact, so its contact is resolved to O(h) like DS's:
    the bounds are DS's, which hold (seen: onset 0.5 h late, duration 1.3 h
    long, impulse 0.2 % and rebound 0.5 % short, plateau force 1e-9)."""
    L, E, RHO, V0, D0 = 10.0, 900.0, 1.0, 10.0, 5.005
    C, MASS = np.sqrt(E / RHO), RHO * L
    bar = load_scene("impacting_bar", {"h": 1e-3, "scheme": "dsn"}).run()
    h = bar.h
    contact = np.nonzero(bar.impulse[:, 0] > 0)[0]
    t_on, t_off = bar.ts[contact[0]], bar.ts[contact[-1]]
    assert D0 / V0 <= t_on + 1e-12 and t_on - D0 / V0 <= h  # the step that holds the contact catches it
    assert abs((t_off - t_on + h) - 2 * L / C) <= 3 * h
    assert np.all(np.diff(contact) == 1)
    assert bar.impulse[:, 0].sum() == pytest.approx(2 * MASS * V0, rel=1e-2)
    assert bar.v[-1].mean() == pytest.approx(-V0, rel=1e-2)
    plateau = bar.observables["tip_force"][(bar.ts > 0.6) & (bar.ts < 1.1)]
    assert np.median(plateau) == pytest.approx(E / C * V0, rel=1e-3)


DP_KEYS = ("m1", "m2", "l1", "l2", "gravity", "theta1", "theta2", "omega1", "omega2", "wall_x", "e")


@pytest.mark.slow
@pytest.mark.parametrize("scheme", ["dsn", "cs", "mj"])
def test_double_pendulum_follows_the_event_driven_reference(scheme):
    """The angles against the event-driven double pendulum (one impact, t* =
    0.605 s), as DS in test_double_pendulum. DSn and CS: second order before
    the impact (seen 30 h²), within 30 (shift + h²) after it (seen 28), the
    rates first order after it (seen 98 h): DS's bounds, widened by a third.
    MJ: first order before (seen 6.9 h); it sees the impact up to two steps
    late (contacts from the predicted position), so 'after' starts 3 steps
    past t*: angles seen 210 h, rates 1.4e3 h."""
    errors = {}
    for h in (2e-3, 5e-4):
        scene = load_scene("double_pendulum", {"h": h, "t_end": 1.2, "scheme": scheme})
        sol = quiet_run(scene)
        assert sol.stats["failed_steps"] == 0
        (r1, r2, w1, w2), impacts = double_pendulum(sol.ts, *(scene.parameters[k] for k in DP_KEYS))
        ref = {"theta1": r1, "theta2": r2, "omega1": w1, "omega2": w2}
        t_star = impacts[0][0]
        shift = np.ceil(t_star / h) * h - t_star
        pre = sol.ts < t_star
        post = sol.ts > t_star + (h if scheme != "mj" else 3 * h)
        err = {k: np.abs(sol.observables[k] - ref[k]) for k in ref}
        theta_pre = max(err[k][pre].max() for k in ("theta1", "theta2"))
        theta_post = max(err[k][post].max() for k in ("theta1", "theta2"))
        omega_post = max(err[k][post].max() for k in ("omega1", "omega2"))
        if scheme == "mj":
            assert theta_pre < 10 * h and theta_post < 300 * h and omega_post < 2000 * h, (h, theta_pre, theta_post,
                                                                                            omega_post)
        else:
            assert theta_pre < 40 * h**2 and theta_post < 40 * (shift + h**2) and omega_post < 150 * h, (
                h, theta_pre, theta_post, omega_post)
        errors[h] = theta_pre, theta_post
    # h / 4: before the impact 16 (second order) or 4 (first) times smaller; after it, at least halved
    assert errors[2e-3][0] > (10.0 if scheme != "mj" else 3.0) * errors[5e-4][0], errors
    assert errors[2e-3][1] > 2.0 * errors[5e-4][1], errors


@pytest.mark.slow
@pytest.mark.parametrize("scheme", ["dsn", "cs", "mj"])
def test_newtons_cradle_follows_the_collision_sequence(scheme):
    """The default cradle (collisions on the step grid) against its exact
    sequence of binary collisions, as DS in test_newtons_cradle: the velocity
    passes down the line in four impacts, momentum is exact and the energy
    kept (e = 1). Positions: DSn and CS to round-off (seen 2e-13 m); MJ moves
    with the mean of the velocities before and after an impact step (θ =
    1/2), so a struck ball lags half a step's travel (seen 0.5 v h), within
    DS's bound for collisions inside steps, (n - 1) v h."""
    scene = load_scene("newtons_cradle", {"scheme": scheme})
    sol = quiet_run(scene)
    exact = scene.exact(sol.ts)
    p, h = scene.parameters, sol.h
    assert sol.stats["failed_steps"] == 0 and np.count_nonzero(sol.impulse.sum(axis=1) > 0) == 4
    final = np.array([sol.observables[f"v{i}"][-1] for i in range(1, 6)])
    np.testing.assert_allclose(final, [exact[f"v{i}"][-1] for i in range(1, 6)], atol=1e-8)  # seen 9e-12
    np.testing.assert_allclose(sol.observables["momentum"], p["mass"] * p["velocity"], rtol=4e-15)
    e0 = 0.5 * p["mass"] * p["velocity"] ** 2
    assert np.abs(sol.observables["energy"] - e0).max() < 1e-8 * e0  # seen 7e-11
    lag = max(np.abs(sol.observables[f"x{i}"] - exact[f"x{i}"]).max() for i in range(1, 6))
    assert lag < (1e-10 if scheme != "mj" else 4 * p["velocity"] * h), lag


# ================================================== integrate equals simulate


def cube_scheme(scene):
    """DS on its matrix-free path whatever the cube's size."""
    scheme = nj.DS(krylov_min_dof=0)
    assert scheme.matrix_free(scene.model)
    return scheme


@pytest.mark.slow
@pytest.mark.parametrize("name, overrides, make_scheme", [
    ("rigid_box", {"z0": 0.3, "t_end": 0.3, "h": 2e-3}, None),  # lands at t ≈ 0.2 s
    ("incline", INCLINE, None),
    # test_krylov's window: the cube lands flat within it, every sub-problem runs
    ("flexible_cube", {"divisions": 2, "h": 3e-5, "t_end": 6e-4, "height": 0.0505, "velocity": -2.43},
     cube_scheme),
    (BLOCK_FILE, {"t_end": 0.3}, None),
], ids=["rigid_box", "incline", "flexible_cube-matrix_free", "system_file"])
def test_integrate_under_jit_equals_simulate(name, overrides, make_scheme):
    scene = load_scene(name, overrides)
    scheme = scene.scheme() if make_scheme is None else make_scheme(scene)
    t1, h = scene.solver["t_end"], scene.solver["h"]
    host = nj.simulate(scene.model, scheme, 0.0, t1, h, scene.q0, scene.v0)
    pure = jax.jit(lambda q0, v0: nj.integrate(scene.model, scheme, 0.0, t1, h, q0, v0))(scene.q0, scene.v0)
    assert pure.n_steps == host.n_steps and not bool(pure.failed) and not host.failed
    assert np.abs(host.impulse).max() > 0  # contacts act in the run (the cube: it lands or is pressed)
    assert_same_run(pure, host)


# ============================================================ batches and sweeps


@pytest.mark.slow
def test_simulate_batch_with_friction_equals_single_runs():
    scene = load_scene("incline", INCLINE)
    hs = [1e-3, 2e-3]
    batch = nj.simulate_batch(scene.model, scene.scheme(), 0.0, 0.3, hs, scene.q0, scene.v0)
    for h, member in zip(hs, batch):
        single = nj.simulate(scene.model, scene.scheme(), 0.0, 0.3, h, scene.q0, scene.v0,
                             observables=scene.observables)
        assert np.abs(single.observables["friction"]).max() > 0  # friction acts
        assert_same_values(member, single, np.abs(single.q).max(), np.abs(single.v).max())


@pytest.mark.slow
def test_vmap_of_integrate_over_friction_equals_single_runs():
    """Two friction coefficients in one vmap(integrate): each member is the
    scene's own run (both slide, mu < tan 0.3)."""
    params, build = parametrize("incline", INCLINE, ["mu"])
    mus = jnp.asarray([0.1, 0.2])

    def one(mu):
        model, q0, v0, _ = build({"mu": mu})
        return nj.integrate(model, nj.DS(), 0.0, 0.3, 1e-3, q0, v0)

    batch = jax.jit(jax.vmap(one))(mus)
    finals = []
    for i, mu in enumerate(mus):
        single = load_scene("incline", {**INCLINE, "mu": float(mu)}).run()
        member = jax.tree_util.tree_map(lambda x, i=i: np.asarray(x[i]), batch)
        assert_same_values(member, single, np.abs(single.q).max(), np.abs(single.v).max())
        finals.append(single.v[-1])
    assert not np.allclose(finals[0], finals[1])  # the members differ: mu reached each one


@pytest.mark.slow
def test_simulate_batch_of_a_system_file_equals_single_runs():
    scene = load_scene(BALL_FILE, {"t_end": 0.6})
    hs = [5e-3, 1e-2]
    batch = nj.simulate_batch(scene.model, scene.scheme(), 0.0, 0.6, hs, scene.q0, scene.v0)
    for h, member in zip(hs, batch):
        single = nj.simulate(scene.model, scene.scheme(), 0.0, 0.6, h, scene.q0, scene.v0)
        assert np.abs(single.impulse).max() > 0  # the floor bounce (t ~ 0.43 s) is in the run
        assert_same_values(member, single, np.abs(single.q).max(), np.abs(single.v).max())


@pytest.mark.slow
def test_sweep_rows_of_a_system_file_equal_single_runs():
    settings = {"t_end": 0.6, "h": 1e-2}
    res = sweep(BALL_FILE, {"contacts.floor.e": [0.5, 0.8]}, overrides=settings, batch_size=2)
    assert [r["contacts.floor.e"] for r in res.rows] == [0.5, 0.8]
    seen = []
    for row in res.rows:
        sol = load_scene(BALL_FILE, {**settings, "contacts.floor.e": row["contacts.floor.e"]}).run()
        assert row["n_steps"] == sol.n_steps == 60 and row["failed_steps"] == 0
        for name, y in sol.observables.items():
            if y.ndim > 1:
                continue
            assert row[f"{name}_final"] == pytest.approx(y[-1], rel=1e-9, abs=1e-9), name
            assert row[f"{name}_min"] == pytest.approx(y.min(), rel=1e-9, abs=1e-9), name
        seen.append(row["ball.vy_final"])
    assert seen[1] > seen[0] > 0.0  # the rows differ: the more elastic floor throws the ball up faster


# ==================================================================== float32


@pytest.mark.slow
@pytest.mark.parametrize("name, overrides", [
    ("incline", INCLINE),
    ("bouncing_ball", {"t_end": 1.0, "scheme": "dsn"}),
    ("bouncing_ball", {"t_end": 1.0, "scheme": "cs"}),
    ("bouncing_ball", {"t_end": 1.0, "scheme": "mj"}),
    (BALL_FILE, {"t_end": 1.0}),
], ids=["incline", "ball-dsn", "ball-cs", "ball-mj", "system_file"])
def test_float32_run_follows_float64(name, overrides, tol=1e-4):
    """As test_precision_and_records::test_float32_run_converges_and_follows_float64:
    float32 (7 digits) within 1e-4 of the coordinates' scale of float64."""
    scene = load_scene(name, overrides)
    ref = scene.run()
    sol = scene.run(dtype="float32")
    assert sol.q.dtype == np.float32 and sol.stats["failed_steps"] == 0
    assert np.abs(ref.impulse).max() > 0
    assert np.abs(sol.q - ref.q).max() < tol * np.abs(ref.q).max()
    assert np.abs(sol.v - ref.v).max() < 10 * tol * max(1.0, np.abs(ref.v).max())  # a step's rounding / h


# ================================================================== identify


@pytest.mark.slow
@pytest.mark.parametrize("name, overrides, true, start, observables", [
    ("rigid_box", {"z0": 0.3, "t_end": 0.3, "h": 2e-3}, {"e": 0.5}, {"e": 0.4}, ["z", "vz"]),
    ("incline", {**INCLINE, "h": 2e-3}, {"mu": 0.2}, {"mu": 0.25}, ["s"]),
    # the tip touches the wall at 0.5 s and leaves it 2L/c later (1.17 s): E sets when it leaves
    ("impacting_bar", {"n_elements": 20, "t_end": 1.5, "h": 2e-3}, {"E": 900.0}, {"E": 1050.0}, ["tip_u"]),
], ids=["rigid_box-e", "incline-mu", "impacting_bar-E"])
def test_identify_recovers_from_synthetic_data(name, overrides, true, start, observables):
    data = synthetic_data(name, {**overrides, **true}, observables, every=2)
    result = identify(name, list(true), data, overrides=overrides, initial=start, true=true)
    for k, v in true.items():
        assert abs(result.recovered[k] / v - 1) < 1e-2, (k, result.recovered[k], result.stop)
    assert result.losses[-1] < 1e-3 * result.losses[0]


def test_identify_with_cs_is_refused_by_name_before_compiling(monkeypatch):
    """CS has no implicit adjoint: identify refuses it, naming CS, while its
    loss is traced (nothing is compiled)."""
    def forbidden(*args, **kwargs):
        raise AssertionError("identify compiled before refusing CS")

    monkeypatch.setattr(jax.stages.Lowered, "compile", forbidden)
    data = Data(t=np.linspace(0.0, 0.2, 11), values={"z": np.linspace(1.0, 0.8, 11)})
    for adjoint in (nj.ImpactTimeAdjoint(), nj.DiscreteAdjoint()):
        with pytest.raises(nj.ConfigError, match=r"CS is not differentiable.*use DS, DSn or MJ"):
            identify("bouncing_ball", ["e"], data, overrides={"scheme": "cs", "h": 1e-2}, adjoint=adjoint)


# ============================================================== command line


@pytest.mark.slow
@pytest.mark.parametrize("name, settings", [
    ("impacting_bar", {"n_elements": 20, "t_end": 0.6, "h": 2e-3}),  # the tip touches the wall at 0.5 s
    ("incline", INCLINE),
    # 648 coordinates: DS takes the matrix-free path by default; the landing is in the window
    ("flexible_cube", {"h": 3e-5, "t_end": 0.0006, "height": 0.0505, "velocity": -2.43}),
])
def test_cli_run_writes_the_trajectory_of_scene_run(name, settings, tmp_path):
    out = tmp_path / name
    args = [f"--set={k}={v}" for k, v in settings.items()]
    assert main(["run", name, *args, "--out", str(out), "--quiet"]) == 0
    data = np.load(out / "trajectory.npz")
    sol = load_scene(name, settings).run()
    assert np.abs(sol.impulse).max() > 0
    for key, expected in (("t", sol.ts), ("q", sol.q), ("v", sol.v), ("impulse", sol.impulse), ("gap", sol.gap),
                          *sol.observables.items()):
        np.testing.assert_allclose(data[key], expected, rtol=0, atol=1e-12 * max(1.0, np.abs(expected).max()),
                                   err_msg=key)
    np.testing.assert_array_equal(data["iterations"], sol.iterations)


# ================================================================== refusals


def test_batch_members_of_different_structure_are_refused_by_name(no_compilation):
    bars = [load_scene("impacting_bar", {"n_elements": n}).model for n in (10, 20)]
    with pytest.raises(nj.ConfigError, match=r"batch member 1 differs in structure from member 0"):
        stack_models(bars)
    blocks = [load_scene("incline", {"mu": mu}).model for mu in (0.2, 0.2, 0.0)]  # friction rows, then none
    with pytest.raises(nj.ConfigError, match=r"batch member 2 differs in structure from member 0"):
        stack_models(blocks)
    stacked = stack_models(blocks[:2])  # same structure, other values: one model with a member axis
    assert stacked.n_dof == blocks[0].n_dof


@pytest.mark.slow
def test_cs_on_a_cube_too_large_for_memory_is_refused_before_compiling(monkeypatch, no_compilation):
    """CS on its dense path (krylov_min_dof=None): the cube at 20 divisions
    (27,783 coordinates) needs 4 dense matrices of 6 GB each. On its
    matrix-free path (the default) the matrices fit in 1 GB and the records
    of 10,000 steps are what is refused."""
    monkeypatch.delenv(memory.SKIP_ENV, raising=False)
    monkeypatch.setattr(memory, "available_memory", lambda: 4e9)
    cube = load_scene("flexible_cube", {"divisions": 20, "scheme": "cs"})
    with pytest.raises(nj.ConfigError, match=r"keeping the records of 10,000 steps needs .* beside "
                                             r"0\.\d+ GB of matrices"):
        cube.run()
    dense = r"27,783 coordinates \(about 4 dense 27,783 x 27,783 iteration matrices"
    with pytest.raises(nj.ConfigError, match=dense):
        nj.simulate(cube.model, nj.CS(krylov_min_dof=None), 0.0, 1e-3, 1e-4, cube.q0, cube.v0)
    # integrate is differentiable, so it refuses CS itself before its memory check
    with pytest.raises(nj.ConfigError, match=r"CS is not differentiable"):
        nj.integrate(cube.model, nj.CS(), 0.0, 1e-3, 1e-4, jnp.asarray(cube.q0), jnp.asarray(cube.v0))


@pytest.mark.slow
def test_a_sweep_over_mu_from_zero_runs_frictionless_and_frictional_members_apart():
    """mu = 0 builds frictionless contacts (mu=None), mu > 0 friction rows: a
    sweep puts them in separate batches (it stacked them, a raw pytree error)
    and each row is its single run."""
    res = sweep("incline", {"mu": [0.0, 0.2]}, overrides={"t_end": 0.05})
    for row in res.rows:
        sol = load_scene("incline", {"t_end": 0.05, "mu": row["mu"]}).run()
        assert row["result"] == "successful"
        assert row["s_final"] == pytest.approx(sol.observables["s"][-1], rel=1e-9, abs=1e-12)
    assert res.rows[0]["s_final"] > res.rows[1]["s_final"] > 0.0  # friction slows the block


@pytest.mark.slow
def test_identify_on_the_matrix_free_path():
    """The cube at its default 5 divisions (648 coordinates) takes DS's
    matrix-free path; E is recovered from the top corner's height through the
    landing (the window of test_krylov, 20 steps)."""
    settings = {"h": 3e-5, "t_end": 0.0006, "height": 0.0505, "velocity": -2.43}
    scene = load_scene("flexible_cube", settings)
    assert scene.model.n_dof >= scene.scheme().krylov_min_dof  # the default switch: the matrix-free path
    true = {"E": float(scene.parameters["E"])}
    data = synthetic_data("flexible_cube", settings, ["x8_uz"])
    result = identify("flexible_cube", ["E"], data, overrides=settings, initial={"E": 1.1 * true["E"]}, true=true)
    assert abs(result.recovered["E"] / true["E"] - 1) < 1e-2, (result.recovered, result.stop)
    assert result.converged and result.losses[-1] < 1e-3 * result.losses[0]


def test_stack_models_under_jit_equals_stacking_concrete_models():
    """stack_models stacks concrete members on the host and traced ones with
    jnp.stack: the same model either way."""
    balls = [BouncingBall(m=m, gravity=9.81, e=0.5) for m in (1.0, 2.0, 3.0)]
    concrete = stack_models(balls)
    traced = jax.jit(lambda ms: stack_models([BouncingBall(m=m, gravity=9.81, e=0.5) for m in ms]))(
        jnp.asarray([1.0, 2.0, 3.0]))
    assert concrete.m.shape == (3,) and concrete.m.dtype == traced.m.dtype
    np.testing.assert_array_equal(concrete.m, traced.m)
    np.testing.assert_array_equal(concrete.e, [0.5, 0.5, 0.5])
