"""Redundant bilateral constraints (a rank-deficient g_q^B): the motion equals
that of the same mechanism without the redundant rows, every constraint
holds, the multipliers are the minimum-norm ones, the redundancy is reported
by name before the run, and joints that no position satisfies together are
refused by name before anything is compiled."""

import subprocess
import sys
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import nsga_jax as nj
from nsga_jax._integrators.linalg import multiplier_rtol
from nsga_jax._integrators.model_terms import consistent_acceleration
from nsga_jax._models.redundancy import RedundantConstraintsWarning, bilateral_redundancy
from nsga_jax._precision import cast_floats
from nsga_jax.scenes import load_scene
from nsga_jax.system import Distance, Pin, RigidBody2D, System, Weld

T_END, H = 0.03, 1e-3


def pendulum(pins: int) -> System:
    """A rigid link pinned ``pins`` times at one point, released horizontal."""
    s = System(dim=2, gravity=[0.0, -9.81])
    s.add_body("link", RigidBody2D(mass=1.0, inertia=0.1, position=[0.5, 0.0], angular_velocity=-1.0,
                                   velocity=[0.0, -0.5]))
    for i in range(pins):
        s.add_joint(f"pivot{i}", Pin("ground", "link", at_b=[-0.5, 0.0]))
    return s


def welded_plate(second_at=(0.0, 0.0)) -> System:
    """A plate welded to the ground twice (at one place unless ``second_at`` moves the second weld)."""
    s = System(dim=2, gravity=[0.0, -9.81])
    s.add_body("plate", RigidBody2D(mass=2.0, inertia=0.1, position=[0.0, 0.0]))
    s.add_joint("left", Weld("ground", "plate", at_a=[0.0, 0.0]))
    s.add_joint("right", Weld("ground", "plate", at_a=list(second_at)))
    return s


def parallelogram(redundant: bool) -> System:
    """A coupler hung from the ground by two parallel massless rods: a closed
    loop (ground, rod, coupler, rod) whose coupler translates on a circle.
    ``redundant``: a third parallel rod at the middle, the classic redundant
    linkage (Grübler counts no mobility; it moves, its rows are dependent)."""
    s = System(dim=2, gravity=[0.0, -9.81])
    s.add_body("coupler", RigidBody2D(mass=1.5, inertia=0.2, position=[0.5, -1.0], velocity=[1.0, 0.0]))
    s.add_joint("rod_left", Distance("ground", "coupler", at_a=[0.0, 0.0], at_b=[-0.5, 0.0], length=1.0))
    s.add_joint("rod_right", Distance("ground", "coupler", at_a=[1.0, 0.0], at_b=[0.5, 0.0], length=1.0))
    if redundant:
        s.add_joint("rod_middle", Distance("ground", "coupler", at_a=[0.5, 0.0], at_b=[0.0, 0.0], length=1.0))
    return s


def run(system: System, scheme, t_end=T_END):
    model, q0, v0 = system.build()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RedundantConstraintsWarning)
        return model, nj.simulate(model, scheme, 0.0, t_end, H, q0, v0)


def violation(model, sol) -> float:
    """The largest bilateral violation of a run, positions [m] and velocities [m/s]."""
    q, v = jnp.asarray(sol.q), jnp.asarray(sol.v)
    g = jax.vmap(model.bilateral)(q)
    rate = jax.vmap(lambda x, y: model.bilateral_jacobian(x) @ y)(q, v)
    return float(max(np.abs(np.asarray(g)).max(), np.abs(np.asarray(rate)).max()))


def assert_constraints_hold(model, sol, tol=1e-8):
    assert violation(model, sol) < tol


SLOW = pytest.mark.slow  # each compiles two runs (some 10-20 s on two cores); DS stays in the default run


@pytest.mark.parametrize("scheme, atol", [(nj.DS(), 1e-9), pytest.param(nj.DSn(), 1e-9, marks=SLOW),
                                          pytest.param(nj.CS(), 1e-9, marks=SLOW),
                                          pytest.param(nj.MJ(), 1e-6, marks=SLOW)], ids=["ds", "dsn", "cs", "mj"])
def test_pinned_twice_moves_as_pinned_once(scheme, atol):
    """Every scheme runs the redundant pin; MJ's Newton stops at its tolerance
    (its trajectories agree to that), and its positions drift as its own do."""
    model1, once = run(pendulum(1), scheme)
    model2, twice = run(pendulum(2), scheme)
    assert np.all(np.isfinite(twice.q))
    np.testing.assert_allclose(twice.q, once.q, atol=atol)
    np.testing.assert_allclose(twice.v, once.v, atol=10 * atol)
    assert_constraints_hold(model2, twice, tol=max(1e-8, 10 * violation(model1, once)))
    # identical rows: the two pins' multipliers [N] add up to the one pin's (to the Newton tolerance,
    # tol_r = 1e-5 relative) and share it
    lam1, lam2 = np.asarray(once.records.lam), np.asarray(twice.records.lam)
    np.testing.assert_allclose(lam2[:, :2] + lam2[:, 2:], lam1, atol=1e-4 * np.abs(lam1).max())
    np.testing.assert_allclose(lam2[:, :2], lam2[:, 2:], atol=1e-3)


def test_two_identical_welds_hold_the_plate_at_rest_and_share_the_load():
    model, sol = run(welded_plate(), nj.DS())
    np.testing.assert_allclose(sol.q, 0.0, atol=1e-12)
    np.testing.assert_allclose(sol.v, 0.0, atol=1e-10)
    q0, v0 = model.initial_state()
    vd = consistent_acceleration(model, 0.0, q0, v0)
    np.testing.assert_allclose(vd, 0.0, atol=1e-12)
    # the regularised multipliers of the steps: each weld carries half the weight m g = 19.62 N (to the
    # shift's round-off, docs/systems.md), the two together all of it
    lam = np.asarray(sol.records.lam[-1])
    np.testing.assert_allclose(lam[:3], lam[3:], rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(lam[1] + lam[4], -2.0 * 9.81, rtol=1e-6)


def test_initial_acceleration_is_finite_and_differentiable_in_float32():
    model, q0, v0 = pendulum(2).build()
    model1, _, _ = pendulum(1).build()
    model32, q32, v32 = cast_floats((model, q0, v0), "float32")
    vd32 = consistent_acceleration(model32, 0.0, q32, v32)
    vd64 = consistent_acceleration(model1, 0.0, q0, v0)
    assert vd32.dtype == jnp.float32 and multiplier_rtol(jnp.float32) > 1e-6
    np.testing.assert_allclose(vd32, vd64, rtol=1e-4, atol=1e-4)
    grad = jax.grad(lambda x: consistent_acceleration(model, 0.0, x, v0)[2])(q0)
    grad1 = jax.grad(lambda x: consistent_acceleration(model1, 0.0, x, v0)[2])(q0)
    np.testing.assert_allclose(grad, grad1, atol=1e-9)


def test_redundant_closed_loop_moves_as_the_loop_without_its_redundant_rod():
    model, redundant = run(parallelogram(True), nj.DS(), t_end=0.05)
    _, plain = run(parallelogram(False), nj.DS(), t_end=0.05)
    np.testing.assert_allclose(redundant.q, plain.q, atol=1e-8)
    np.testing.assert_allclose(redundant.v, plain.v, atol=1e-7)
    assert_constraints_hold(model, redundant)
    np.testing.assert_allclose(np.asarray(redundant.q)[:, 2], 0.0, atol=1e-10)  # the coupler only translates


def test_the_redundancy_is_reported_by_name_before_the_run():
    assert bilateral_redundancy(*pendulum(1).build()[:2]) is None
    model, q0, v0 = parallelogram(True).build()
    report = bilateral_redundancy(model, q0)
    assert (report.n_rows, report.rank, report.n_redundant) == (3, 2, 1)
    assert report.redundant == ("joints.rod_middle[0]",)
    assert report.parts == ("joints.rod_left", "joints.rod_right", "joints.rod_middle")
    model, q0, v0 = pendulum(2).build()
    with pytest.warns(RedundantConstraintsWarning, match=r"rank 2 for 4 rows.*joints\.pivot1\[0\], "
                                                         r"joints\.pivot1\[1\]\) among joints\.pivot0, joints\.pivot1"):
        sol = nj.simulate(model, nj.DS(), 0.0, 2 * H, H, q0, v0)
    assert sol.warnings[0].startswith("redundant bilateral constraints")


def test_welds_at_different_places_are_refused_by_name_before_compiling(no_compilation):
    with pytest.raises(nj.ConfigError, match=r"joints\.left and joints\.right contradict each other.*0\.05 m"):
        welded_plate((0.1, 0.0)).build()
    model = welded_plate((0.1, 0.0)).model()  # unchecked: simulate refuses it as well
    q0, v0 = model.initial_state()
    with pytest.raises(ValueError, match=r"joints\.left and joints\.right contradict each other"):
        nj.simulate(model, nj.DS(), 0.0, T_END, H, q0, v0)


def test_a_misplaced_but_satisfiable_joint_keeps_its_own_message():
    s = System(dim=2)
    s.add_body("link", RigidBody2D(mass=1.0, inertia=0.1, position=[0.5, 0.0]))
    s.add_joint("pivot", Pin("ground", "link", at_a=[0.01, 0.0], at_b=[-0.5, 0.0]))
    with pytest.raises(nj.ConfigError, match=r"joints\.pivot: violated at the initial state"):
        s.build()


def test_every_member_of_a_batch_carries_the_redundancy_in_its_warnings():
    model, q0, v0 = pendulum(2).build()
    with pytest.warns(RedundantConstraintsWarning):
        sols = nj.simulate_batch(model, nj.DS(), 0.0, 4 * H, [H, 2 * H], q0, v0)
    for sol in sols:
        assert sol.warnings[0] == bilateral_redundancy(model, q0).text()


TWICE_PINNED = """
[system]
dim = 2
gravity = [0.0, -9.81]

[bodies.link]
type = "rigid_body_2d"
mass = 1.0
inertia = 0.1
position = [0.5, 0.0]
""" + "".join(f"""
[joints.pivot{i}]
type = "pin"
body_a = "ground"
body_b = "link"
at_b = [-0.5, 0.0]
""" for i in range(2)) + """
[solver]
h = 1e-3
t_end = 0.003
"""


def test_the_command_line_prints_the_redundancy_once_in_its_own_words(tmp_path):
    """One ``warning:`` line, without Python's own (file, line and class) even
    where Python shows every warning (``-W default``)."""
    path = tmp_path / "twice.toml"
    path.write_text(TWICE_PINNED)
    proc = subprocess.run([sys.executable, "-W", "default", "-m", "nsga_jax._cli", "run", str(path), "--out",
                           str(tmp_path / "out"), "--quiet", "--no-cache"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = [line for line in proc.stderr.splitlines() if "redundant bilateral constraints" in line]
    assert len(lines) == 1 and lines[0].startswith("warning: redundant bilateral constraints: g_q^B(q0) has rank 2")
    assert "RedundantConstraintsWarning" not in proc.stderr


def test_a_sweep_reports_the_redundancy_once_before_it_runs(tmp_path, monkeypatch, capsys, scene_registry):
    """From Python: warned once and kept in ``SweepResult.warnings``; from the
    command line: one ``warning:`` line, as for a run."""
    from nsga_jax._cli import main
    from nsga_jax._sweep import sweep

    path = tmp_path / "twice.toml"
    path.write_text(TWICE_PINNED)
    scene = load_scene(str(path))
    expected = bilateral_redundancy(scene.model, scene.q0).text()
    with pytest.warns(RedundantConstraintsWarning) as caught:
        result = sweep(str(path), {"bodies.link.mass": [1.0, 2.0, 3.0]}, batch_size=2)
    assert [str(w.message) for w in caught if w.category is RedundantConstraintsWarning] == [expected]
    assert result.warnings == [expected] and len(result.rows) == 3 and not result.failed
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    assert main(["sweep", str(path), "--grid", "bodies.link.mass=1:2:2", "--quiet", "--no-plots"]) == 0
    err = capsys.readouterr().err.splitlines()
    assert [line for line in err if "redundant" in line] == [f"warning: {expected}"]
