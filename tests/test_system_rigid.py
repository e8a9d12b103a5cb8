"""The rigid scenes built as systems equal the hand-written models; the 3D
rigid body and the 3D joints (revolute, spherical, weld) hold and move as
rigid-body mechanics says."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from reference_models import BouncingBall, RigidBody, RigidPendulum

import nsga_jax as nj
from nsga_jax._elements.rigid_body import box_inertia, box_vertices
from nsga_jax.scenes import load_scene
from nsga_jax.system import Ground, Pin, PointMass, Revolute, RigidBody3D, System, Weld3D

SCENES = ("bouncing_ball", "rigid_pendulum", "rigid_box")
FLAGS = ("n_dof", "n_bilateral", "n_unilateral", "constant_mass", "linear_force", "velocity_dependent_force",
         "linear_constraints")


def hand_written(scene):
    """The hand-written model the scene was built from before it was a system."""
    p = scene.parameters
    if scene.name == "bouncing_ball":
        return BouncingBall(m=p["mass"], gravity=p["gravity"], e=p["e"])
    if scene.name == "rigid_pendulum":
        side = float(np.sign(scene.q0[0] - p["wall_x"]))
        return RigidPendulum(m=p["mass"], length=p["length"], gravity=p["gravity"], wall_x=p["wall_x"], side=side,
                             e=p["e"])
    sides = jnp.array([p["lx"], p["ly"], p["lz"]])
    return RigidBody(mass_=p["mass"], inertia=box_inertia(p["mass"], sides), points=box_vertices(sides),
                     gravity=p["gravity"], floor_z=0.0, e=jnp.full(8, p["e"]), size=0.5 * jnp.linalg.norm(sides),
                     contact=p["floor"] == "on")


@pytest.mark.parametrize("name, overrides", [(name, {}) for name in SCENES] + [("rigid_box", {"floor": "off"})])
def test_derived_structure_equals_the_declared_one(name, overrides):
    scene = load_scene(name, overrides)
    old = hand_written(scene)
    for flag in FLAGS:
        assert getattr(scene.model, flag) == getattr(old, flag), flag
    # the flags against the model's functions: test_check_model.py, for every built-in scene


@pytest.mark.parametrize("name", SCENES)
def test_model_functions_equal_the_hand_written_ones(name):
    scene = load_scene(name)
    new, old = scene.model, hand_written(scene)
    rng = np.random.default_rng(1)
    q = jnp.asarray(scene.q0 + 0.1 * rng.standard_normal(new.n_dof))
    v = jnp.asarray(rng.standard_normal(new.n_dof))
    mu = jnp.asarray(rng.standard_normal(new.n_constraints))
    for fn, args in (("mass", (q,)), ("force", (q, v, 0.3)), ("constraints", (q,)), ("constraint_jacobian", (q,)),
                     ("constraint_curvature", (q, mu)), ("velocity_constraint_gradient", (q, v))):
        expected = getattr(old, fn)(*args)  # round-off: a dot product may fuse its multiply-adds
        scale = max(1.0, float(np.abs(expected).max()))
        np.testing.assert_allclose(getattr(new, fn)(*args), expected, rtol=0, atol=1e-15 * scale, err_msg=fn)
    np.testing.assert_array_equal(new.restitution, old.restitution)
    assert float(new.mbar) == float(old.mbar)
    assert new.energy(q, v) == pytest.approx(float(old.energy(q, v)), rel=1e-14)
    speed = old.angular_speed(q, v)  # the coarse-step warning's rate: the box's |ω|, the pendulum rod's |v| / l
    assert new.angular_speed(q, v) == (None if speed is None else pytest.approx(speed, rel=1e-14))


def _same_run(name, overrides):
    scene = load_scene(name, overrides)
    scheme = scene.scheme()
    t_end, h = scene.solver["t_end"], scene.solver["h"]
    new = nj.simulate(scene.model, scheme, 0.0, t_end, h, scene.q0, scene.v0)
    old = nj.simulate(hand_written(scene), scheme, 0.0, t_end, h, scene.q0, scene.v0)
    assert new.impulse.max() > 0.0  # the run has impacts
    for x, y in ((new.q, old.q), (new.v, old.v), (new.impulse, old.impulse)):
        assert np.abs(x - y).max() <= 1e-12 * np.abs(y).max()


def test_ball_run_equals_the_hand_written_model():
    _same_run("bouncing_ball", {"t_end": 1.0})


@pytest.mark.parametrize("name, overrides", [("rigid_pendulum", {"t_end": 1.0}), ("rigid_box", {"t_end": 0.5})])
def test_system_run_equals_the_hand_written_model(name, overrides):
    # the first impacts: the pendulum's at t ≈ 0.7 s, the box's at t ≈ 0.42 s
    _same_run(name, overrides)


# ------------------------------------------------------------ 3D parts


def _tilted():
    """A rotation with no axis along a coordinate axis."""
    a, b, c = 0.4, -0.7, 1.1
    Rx = jnp.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])
    Ry = jnp.array([[np.cos(b), 0.0, np.sin(b)], [0.0, 1.0, 0.0], [-np.sin(b), 0.0, np.cos(b)]])
    Rz = jnp.array([[np.cos(c), -np.sin(c), 0.0], [np.sin(c), np.cos(c), 0.0], [0.0, 0.0, 1.0]])
    return Rz @ Ry @ Rx


def test_part_jacobians_against_finite_differences():
    system = System(dim=3)
    system.add_body("a", RigidBody3D(2.0, [0.3, 0.4, 0.5], position=[0.0, 0.0, -0.5], rotation=_tilted()))
    system.add_body("b", RigidBody3D(1.0, jnp.diag(jnp.array([0.1, 0.2, 0.25])), position=[0.0, 0.0, -1.5]))
    system.add_joint("hinge", Revolute("ground", "a", axis=[1.0, 0.2, 0.0], at_b=[0.1, 0.2, 0.5]))
    system.add_joint("knee", Revolute("a", "b", axis=[0.0, 0.3, 1.0], axis_b=[1.0, 0.0, 0.2], at_a=[0.0, 0.0, -0.5],
                                      at_b=[0.0, 0.0, 0.5], scale=0.7))
    system.add_joint("ball", Pin("a", "b", at_a=[0.2, 0.0, -0.5], at_b=[0.0, 0.1, 0.5]))
    system.add_joint("weld", Weld3D("b", "a", rotation=_tilted(), at_b=[0.3, 0.0, 0.0], scale=0.5))
    system.add_joint("fixed", Weld3D("ground", "b"))
    model = system.model()
    assert model.n_bilateral == 2 * 6 + 5 + 5 + 3 + 6 + 6
    q = jnp.asarray(model.initial_state()[0] + 0.2 * np.random.default_rng(2).standard_normal(model.n_dof))
    G = eqx.filter_jit(lambda m, x: m.constraint_jacobian(x))(model, q)
    eps = 1e-6
    g = jax.vmap(eqx.filter_jit(lambda m, x: m.constraints(x)), in_axes=(None, 0))
    steps = eps * jnp.eye(model.n_dof)
    fd = ((g(model, q + steps) - g(model, q - steps)) / (2 * eps)).T
    np.testing.assert_allclose(G, fd, atol=1e-8)
    # points and frames are affine in natural coordinates: a joint to the ground is affine in q
    assert Revolute("ground", "a", axis=[1.0, 0.0, 0.0]).is_linear((Ground(3), model.body("a")))
    assert not Revolute("a", "b", axis=[1.0, 0.0, 0.0]).is_linear((model.body("a"), model.body("b")))


def test_rigid_body_initial_state_and_anchors():
    R0 = _tilted()
    omega = jnp.array([1.0, -2.0, 0.5])
    body = RigidBody3D(3.0, [0.2, 0.3, 0.4], position=[1.0, 2.0, 3.0], rotation=R0, velocity=[0.1, 0.0, -0.1],
                       angular_velocity=omega)
    q, v = body.initial_state()
    X = jnp.array([0.3, -0.2, 0.1])
    np.testing.assert_allclose(body.position(q, X, None), jnp.array([1.0, 2.0, 3.0]) + R0 @ X, atol=1e-15)
    np.testing.assert_allclose(body.angular_velocity(q, v), omega, atol=1e-14)
    # a point's velocity is that of the rigid motion: v_c + ω × (R X)
    _, xdot = jax.jvp(lambda x: body.position(x, X, None), (q,), (v,))
    np.testing.assert_allclose(xdot, jnp.array([0.1, 0.0, -0.1]) + jnp.cross(omega, R0 @ X), atol=1e-14)
    assert np.abs(body.bilateral(q)).max() < 1e-15
    # the default size is the half-diagonal of a box: sqrt(1.5 tr J / m)
    sides = jnp.array([0.1, 0.2, 0.3])
    box = RigidBody3D(46.8, box_inertia(46.8, sides), position=[0.0, 0.0, 0.0])
    assert float(box.size) == pytest.approx(0.5 * float(jnp.linalg.norm(sides)), rel=1e-14)


@pytest.mark.parametrize("make, match", [
    (lambda: RigidBody3D(1.0, [1.0, 1.0, 2.5], position=[0.0, 0.0, 0.0]), "triangle inequality"),
    (lambda: RigidBody3D(1.0, [1.0, 1.0, 1.0], position=[0.0, 0.0]), "position must be a vector of 3"),
    (lambda: RigidBody3D(1.0, [1.0, 1.0, 1.0], position=[0.0, 0.0, 0.0], rotation=-jnp.eye(3)), "determinant"),
    (lambda: Revolute("ground", "a", axis=[0.0, 0.0, 0.0]), "axis must be a non-zero vector"),
])
def test_invalid_parts_are_refused(make, match):
    with pytest.raises(nj.ConfigError, match=match):
        make()


def test_a_revolute_joint_needs_oriented_bodies():
    system = System(dim=3)
    system.add_body("p", PointMass(1.0, [0.0, 0.0, -1.0]))
    system.add_joint("hinge", Revolute("ground", "p", axis=[1.0, 0.0, 0.0], at_a=[0.0, 0.0, -1.0]))
    with pytest.raises(nj.ConfigError, match=r"joints.hinge: body b \(PointMass\) has no orientation"):
        system.model()


def hinged_pendulum():
    """A tilted body on a hinge along the world x axis through the origin,
    its centre of mass at ``d`` below the hinge, released at 0.8 rad."""
    theta0, d = 0.8, 0.5
    turn = jnp.array([[1.0, 0.0, 0.0], [0.0, np.cos(theta0), -np.sin(theta0)], [0.0, np.sin(theta0), np.cos(theta0)]])
    R0 = turn @ _tilted()
    system = System(dim=3, gravity=[0.0, 0.0, -9.81])
    inertia = jnp.array([0.05, 0.08, 0.11])
    system.add_body("link", RigidBody3D(2.0, inertia, position=turn @ jnp.array([0.0, 0.0, -d]), rotation=R0))
    # the hinge point is at body coordinates R0^T (0 - r0)
    hinge_at = R0.T @ (-(turn @ jnp.array([0.0, 0.0, -d])))
    system.add_joint("hinge", Revolute("ground", "link", axis=[1.0, 0.0, 0.0], axis_b=R0.T @ jnp.array([1.0, 0.0, 0.0]),
                                       at_b=hinge_at))
    model, q0, v0 = system.build()
    J_hinge = float(jnp.array([1.0, 0.0, 0.0]) @ (R0 @ jnp.diag(inertia) @ R0.T) @ jnp.array([1.0, 0.0, 0.0]))
    return model, q0, v0, theta0, 9.81 * 2.0 * d / (J_hinge + 2.0 * d**2)


def test_revolute_joint_holds_and_keeps_the_motion_in_its_plane():
    model, q0, v0, theta0, k = hinged_pendulum()
    h, t_end = 1e-3, 0.5
    sol = nj.simulate(model, nj.DS(rho_inf=1.0), 0.0, t_end, h, q0, v0)
    assert sol.stats["failed_steps"] == 0
    assert np.abs(np.asarray(sol.records.bilateral)).max() < 1e-10  # the hinge and rigidity, every step
    assert np.abs(np.asarray(sol.records.bilateral_rate)).max() < 1e-10
    body = model.body("link")
    omega = jax.vmap(body.angular_velocity)(sol.q, sol.v)
    assert np.abs(omega[:, 1:]).max() < 1e-9 * np.abs(omega[:, 0]).max()  # turning about the hinge only
    assert np.abs(sol.q[:, 0]).max() < 1e-12  # the centre of mass stays in the plane x = 0
    # the angle against the physical pendulum θ'' = -k sin θ (an independent ODE)
    theta = np.arctan2(sol.q[:, 1], -sol.q[:, 2])
    ref = diffrax.diffeqsolve(diffrax.ODETerm(lambda t, y, args: jnp.stack([y[1], -k * jnp.sin(y[0])])),
                              diffrax.Dopri8(), 0.0, t_end, 1e-3, jnp.array([theta0, 0.0]),
                              saveat=diffrax.SaveAt(ts=jnp.asarray(sol.ts)),
                              stepsize_controller=diffrax.PIDController(rtol=1e-12, atol=1e-12))
    assert np.abs(theta - np.asarray(ref.ys[:, 0])).max() < 1e-4


def test_spherical_joint_holds_and_keeps_the_vertical_angular_momentum():
    """A box on a ball joint at the origin, spinning and swinging: gravity and
    the joint's force have no moment about the vertical through the pivot."""
    system = System(dim=3, gravity=[0.0, 0.0, -9.81])
    R0 = _tilted()
    r0 = jnp.array([0.3, 0.0, -0.4])
    system.add_body("top", RigidBody3D(1.5, [0.02, 0.03, 0.04], position=r0, rotation=R0,
                                       velocity=jnp.cross(jnp.array([0.0, 2.0, 3.0]), r0),
                                       angular_velocity=[0.0, 2.0, 3.0]))
    system.add_joint("ball", Pin("ground", "top", at_b=R0.T @ -r0))
    model, q0, v0 = system.build()
    sol = nj.simulate(model, nj.DS(rho_inf=1.0), 0.0, 0.5, 5e-4, q0, v0)
    assert np.abs(np.asarray(sol.records.bilateral)).max() < 1e-10
    assert np.abs(np.asarray(sol.records.bilateral_rate)).max() < 1e-10
    Lz = jax.vmap(model.body("top").angular_momentum)(sol.q, sol.v)[:, 2]
    assert np.abs(Lz - Lz[0]).max() < 1e-6 * np.abs(Lz[0])
    energy = jax.vmap(model.energy)(sol.q, sol.v)
    assert np.abs(energy - energy[0]).max() < 1e-4 * np.abs(energy[0])


def test_welded_bodies_move_as_one():
    """Two bodies welded together fly and spin as one rigid body: the weld
    holds, the relative rotation stays, and the angular momentum about the
    common centre of mass is kept."""
    system = System(dim=3)
    omega = jnp.array([3.0, -1.0, 2.0])
    system.add_body("a", RigidBody3D(1.0, [0.01, 0.02, 0.025], position=[0.0, 0.0, 0.0], angular_velocity=omega))
    offset = jnp.array([0.2, 0.1, 0.0])
    system.add_body("b", RigidBody3D(2.0, [0.03, 0.02, 0.04], position=offset, rotation=_tilted(),
                                     velocity=jnp.cross(omega, offset), angular_velocity=omega))
    system.add_joint("weld", Weld3D("a", "b", at_a=offset, rotation=_tilted()))
    model, q0, v0 = system.build()
    sol = nj.simulate(model, nj.DS(rho_inf=1.0), 0.0, 0.3, 5e-4, q0, v0)
    assert np.abs(np.asarray(sol.records.bilateral)).max() < 1e-10
    a, b = model.body("a"), model.body("b")
    qa, qb = sol.q[:, model.coordinates("a")], sol.q[:, model.coordinates("b")]
    relative = jax.vmap(lambda x, y: a.rotation(x).T @ b.rotation(y))(qa, qb)
    assert np.abs(relative - _tilted()).max() < 1e-9
    va, vb = sol.v[:, model.coordinates("a")], sol.v[:, model.coordinates("b")]
    momentum = jax.vmap(a.angular_momentum)(qa, va) + jax.vmap(b.angular_momentum)(qb, vb)  # about the origin
    linear = 1.0 * va[:, :3] + 2.0 * vb[:, :3]
    assert np.abs(linear - linear[0]).max() < 1e-9
    assert np.abs(momentum - momentum[0]).max() < 1e-6 * np.linalg.norm(momentum[0])
