"""The box_stack scene: N boxes stacked on a floor with friction at every
contact stay at rest, the system-file example is the scene, a pushed stack
comes to rest; and the face contact it is built from (a point of one body
against a face of another that moves and turns)."""

from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import nsga_jax
from nsga_jax._system.contacts import tangent_basis
from nsga_jax.scenes import load_scene
from nsga_jax.system import FaceContact, RigidBody2D, RigidBody3D

STACK = Path(__file__).resolve().parents[1] / "nsga_jax" / "configs" / "systems" / "stacked_boxes.toml"

pytestmark = pytest.mark.usefixtures("scene_registry")  # the system file registers a scene (conftest)


# ------------------------------------------------------------------ the face contact

def _turned_box_2d(theta=0.3):
    return RigidBody2D(1.0, 0.1, position=[0.4, -0.2], angle=theta, velocity=[0.5, -1.0], angular_velocity=2.0)


def test_the_gap_is_the_distance_to_the_turning_face_and_the_slip_turns_with_it():
    """Gap n_b · (x_a - o_b) and slip (v_a - v_b) · t on a face of a turned,
    spinning body, against the formulas written out in world coordinates."""
    a = RigidBody2D(1.0, 0.1, position=[0.1, 0.7], angle=-0.2, velocity=[1.0, 0.3], angular_velocity=-1.5)
    b = _turned_box_2d()
    contact = FaceContact("a", "b", points=[[0.05, -0.1], [-0.05, -0.1]], normal=[0.0, 2.0], origin=[0.0, 0.1],
                          e=0.0, mu=0.5)
    (qa, va), (qb, vb) = a.initial_state(), b.initial_state()

    def rot(t):
        return jnp.array([[jnp.cos(t), -jnp.sin(t)], [jnp.sin(t), jnp.cos(t)]])

    n, t = rot(qb[2]) @ jnp.array([0.0, 1.0]), rot(qb[2]) @ jnp.array([-1.0, 0.0])
    o = qb[:2] + rot(qb[2]) @ jnp.array([0.0, 0.1])
    x = qa[:2] + (rot(qa[2]) @ contact.points.T).T
    np.testing.assert_allclose(contact.evaluate((a, b), (qa, qb)), (x - o) @ n, rtol=1e-14, atol=1e-15)

    def velocity(q, v, p):  # of the material point of a planar body at world point p
        r = p - q[:2]
        return v[:2] + v[2] * jnp.stack([-r[..., 1], r[..., 0]], axis=-1)

    slip = contact.slip_velocity((a, b), (qa, qb), (va, vb))
    np.testing.assert_allclose(slip[:, 0], (velocity(qa, va, x) - velocity(qb, vb, x)) @ t, rtol=1e-13)


def test_a_bounded_face_reaches_the_points_over_it_only():
    """Beyond an edge (with the margin) or deeper than ``depth`` a point is
    out of reach: its gap is the constant sum(half_extent)."""
    ground = nsga_jax.system.Ground(3)
    box = RigidBody3D(1.0, [1.0, 1.0, 1.0], position=[0.0, 0.0, 0.0])
    points = [[0.0, 0.0, 0.02], [0.25, 0.0, -0.01], [0.0, 0.32, 0.0], [0.0, 0.0, -0.2], [0.2, -0.29, -0.05]]
    half = jnp.abs(tangent_basis(jnp.array([0.0, 0.0, 1.0]))) @ jnp.array([0.2, 0.3, 0.0])  # x: 0.2, y: 0.3
    contact = FaceContact("box", "ground", points=points, normal=[0.0, 0.0, 1.0], origin=[0.0, 0.0, 0.0], e=0.0,
                          half_extent=half, margin=0.01, depth=0.1)
    q = box.initial_state()[0]
    gap = contact.evaluate((box, ground), (q, jnp.zeros(0)))
    np.testing.assert_allclose(gap, [0.02, 0.5, 0.5, 0.5, -0.05], atol=1e-15)
    with pytest.raises(nsga_jax.ConfigError, match="margin narrows the face to nothing"):
        FaceContact("box", "ground", points=points, normal=[0.0, 0.0, 1.0], origin=[0.0, 0.0, 0.0], e=0.0,
                    half_extent=half, margin=-0.2)


def test_the_face_contact_is_differentiable_in_its_numbers():
    b = _turned_box_2d()
    a = RigidBody2D(1.0, 0.1, position=[0.3, 0.5])

    def gap(mu, origin_y):
        c = FaceContact("a", "b", points=[[0.0, -0.1]], normal=[0.0, 1.0], origin=jnp.stack([0.0, origin_y]),
                        e=0.0, mu=mu)
        return c.evaluate((a, b), (a.initial_state()[0], b.initial_state()[0]))[0]

    assert jax.grad(gap, argnums=1)(0.5, 0.1) == pytest.approx(-1.0, rel=1e-12)  # the face moves along its normal


# ------------------------------------------------------------------ the scene

def _at_rest(sol, tol=1e-9):
    assert sol.stats["result"] == "successful" and sol.stats["failed_steps"] == 0
    assert float(np.max(sol.observables["drift"])) < tol
    assert sol.stats["max_penetration"] <= 1e-9


@pytest.mark.parametrize("dim, n", [(2, 3), (3, 2)])
def test_a_stack_stays_at_rest(dim, n):
    """Every corner of every box in contact with friction (four bottom corners
    per box in 3D: the contact Jacobian is rank-deficient): the stack keeps
    its place to 1e-9 m and every step converges."""
    scene = load_scene("box_stack", {"dim": dim, "n_boxes": n, "t_end": 0.2})
    assert scene.model.n_friction == (2 * n - 1) * 2**dim  # contact points: every corner on the floor, 2^dim a pair
    sol = scene.run()
    _at_rest(sol)
    assert sol.stats["iterations"]["position"]["max"] <= 5


@pytest.mark.parametrize("dim, n, mu", [(3, 3, 0.5), (2, 4, 0.0)])
def test_touching_boxes_take_one_iteration_whatever_the_sign_of_round_off(dim, n, mu):
    """A stack at rest (3D with friction, planar without), each interface
    open, closed or touching by a few ulps of the boxes' heights (±1e-16 m):
    after the smooth step, which moves every box alike, the interface gaps
    are that round-off, and the contacts are at the edge of complementarity
    (Λ = 0, gap = 0). Newton's matrix treats them as closed whatever the sign
    (``linearised_active``), so every position correction and velocity jump
    takes one iteration; with the sign deciding (an open gap linearised as
    open), the first position correction took 3 (2 to 4 without friction),
    and ten 3D boxes 41 (docs/friction.md)."""
    scene = load_scene("box_stack", {"dim": dim, "n_boxes": n, "mu": mu})
    model, scheme, h = scene.model, scene.scheme(), scene.solver["h"]
    step = jax.jit(lambda s: scheme.step(model, scheme.prepare(model, h, 0.0), s, h))
    for gap in (0.0, 1e-16, -1e-16):
        q0 = np.array(scene.q0).reshape(n, -1)
        q0[:, dim - 1] += gap * np.arange(n)
        state = scheme.init(model, 0.0, jnp.asarray(q0.ravel()), scene.v0)
        for _ in range(2):
            state, out = step(state)
            assert int(out.result) == 0
            np.testing.assert_array_equal(np.asarray(out.newton.iterations), [1, 1, 1])


def test_the_system_file_is_the_scene():
    """configs/systems/stacked_boxes.toml writes out the scene at its defaults, part by part."""
    from_file, scene = load_scene(STACK), load_scene("box_stack")
    assert eqx.tree_equal(from_file.model, scene.model)
    np.testing.assert_array_equal(from_file.q0, scene.q0)
    np.testing.assert_array_equal(from_file.v0, scene.v0)
    pushed = load_scene(STACK, {"bodies.box3.velocity": [2.0, 0.0]})
    np.testing.assert_array_equal(pushed.v0, load_scene("box_stack", {"push": 2.0}).v0)


@pytest.mark.slow
@pytest.mark.parametrize("dim", [2, 3])
def test_ten_boxes_rest(dim):
    """Ten boxes for 1 s in 2D, 10 steps in 3D (456 contact rows: a step costs about a second here; the
    benchmark, experiments/benchmarks/bench_stack.py, runs longer). In 3D 1 to 3 of the first 10 steps
    failed until the pivot of redundant sticking contacts took the minimum-norm point where it changes the
    active set, and otherwise the event along ±n with the smaller law rows (docs/friction.md)."""
    _at_rest(load_scene("box_stack", {"dim": dim, "n_boxes": 10, "t_end": 1.0 if dim == 2 else 0.01}).run())


@pytest.mark.parametrize("restarts", [False, True])
def test_the_step_that_cycled_converges_without_a_restart(monkeypatch, restarts):
    """Six planar boxes, the top one pushed at 2 m/s, at t = 0.037 s (the
    state saved from a run): the next step's velocity jump cycled between a
    contact's stick and slip branches until the iteration cap, and only a
    run from its start with the tangential penalties rescaled
    (``RESTART_PENALTIES``) converged. With Newton's matrix closing the
    contacts at σ = ±round-off (``linearised_active``) the first run
    converges, with or without restarts, in the same iterations: the cycle
    was a path through those degenerate contacts. (The restarts themselves
    are tested on their own problems in test_newton.py.)"""
    from nsga_jax._integrators import friction
    from nsga_jax._integrators.base import StepState

    if not restarts:
        monkeypatch.setattr(friction, "RESTART_PENALTIES", ())
    saved = np.load(Path(__file__).parent / "data" / "box_stack_6_pushed_step37.npz")
    scene = load_scene("box_stack", {"n_boxes": 6, "push": 2.0})
    model, scheme, h = scene.model, scene.scheme(), scene.solver["h"]
    state = StepState(**{k: jnp.asarray(saved[k]) for k in ("t", "q", "v", "vd", "a")})
    _, out = jax.jit(lambda s: scheme.step(model, scheme.prepare(model, h, 0.0), s, h))(state)
    assert int(out.result) == 0
    assert int(out.newton.iterations[2]) < 10 < scene.solver["max_iter"]


@pytest.mark.slow
def test_ten_pushed_planar_boxes_come_to_rest_without_a_failed_step():
    """Ten planar boxes, the top one pushed at 2 m/s, for 3 s: 45 steps failed
    (2-cycles of the semi-smooth Newton) before the restarts with another
    tangential penalty; now none does and the stack ends at rest."""
    sol = load_scene("box_stack", {"n_boxes": 10, "push": 2.0, "t_end": 3.0}).run(throw=False)
    assert sol.stats["failed_steps"] == 0
    assert float(sol.observables["speed"][-1]) < 1e-9


@pytest.mark.slow
@pytest.mark.parametrize("dim", [2, 3])
def test_a_pushed_stack_comes_to_rest(dim):
    """The top box, pushed at 2 m/s, slides off, tips over the edge and falls
    to the floor; every step converges and everything ends at rest."""
    sol = load_scene("box_stack", {"dim": dim, "push": 2.0, "t_end": 2.0}).run(throw=False)
    assert sol.stats["failed_steps"] == 0
    assert float(sol.observables["speed"][-1]) < 1e-6
    assert float(sol.observables["top_height"][-1]) < 0.15  # on the floor, beside the stack
