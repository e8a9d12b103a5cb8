"""Parts of a system: Jacobians against finite differences, derived structure
against the functions, and the builder's named errors."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import nsga_jax as nj
from nsga_jax.system import (
    Beam2D,
    Distance,
    Gravity,
    Pin,
    PlaneContact,
    PointMass,
    PrescribedForce,
    RigidBody2D,
    Slider,
    SphereContact,
    SpringDamper,
    System,
    TorsionalSpring,
    Weld,
)


def mechanism() -> System:
    """Every planar part at once: a rigid link pinned to ground, a beam welded
    to it, a slider, a point mass on a spring, a rod, contacts, loads."""
    s = System(dim=2, gravity=[0.0, -9.81])
    s.add_body("link", RigidBody2D(mass=2.0, inertia=0.1, position=[0.3, 0.0], angle=0.0))
    s.add_body("beam", Beam2D(E=2e8, nu=0.3, rho=800.0, area=1e-3, second_moment=1e-8, length=0.5, n_elements=2,
                              position=[0.6, 0.0]))
    s.add_body("block", RigidBody2D(mass=1.0, inertia=0.01, position=[1.1, 0.0]))
    s.add_body("ball", PointMass(0.5, [0.0, -1.0]))
    s.add_joint("pivot", Pin("ground", "link", at_a=[0.0, 0.0], at_b=[-0.3, 0.0]))
    s.add_joint("clamp", Weld("link", "beam", at_a=[0.3, 0.0], node_b=0))
    s.add_joint("rail", Slider("ground", "block", axis=[1.0, 0.0], at_a=[0.0, 0.0]))
    s.add_joint("rod", Distance("beam", "block", node_a=-1, length=0.0 + 1e-9 + 1.0, at_b=[-1.0, 0.0]))
    s.add_contact("stop", PlaneContact("block", normal=[-1.0, 0.0], origin=[2.0, 0.0], e=0.5,
                                       points=[[0.1, 0.05], [0.1, -0.05]]))
    s.add_contact("floor", PlaneContact("beam", normal=[0.0, 1.0], origin=[0.0, -0.5], e=0.0, nodes=[1, -1]))
    s.add_contact("balls", SphereContact("ball", "link", radius_a=0.1, radius_b=0.05, e=1.0))
    s.add_force("spring", SpringDamper("ground", "ball", stiffness=50.0, rest_length=0.8, damping=0.3,
                                       at_a=[0.0, 0.0]))
    s.add_force("torsion", TorsionalSpring("ground", "link", stiffness=3.0, damping=0.2))
    s.add_force("push", PrescribedForce("block", [1.0, 0.0], amplitude=2.0, frequency=1.5, at=[0.0, 0.1]))
    s.add_force("motor", PrescribedForce("link", [1.0], amplitude=0.5, torque=True))
    return s


def random_state(model, seed=0, spread=0.05):
    rng = np.random.default_rng(seed)
    q0, v0 = model.initial_state()
    return (q0 + spread * jnp.asarray(rng.standard_normal(q0.shape)),
            v0 + spread * jnp.asarray(rng.standard_normal(q0.shape)))


def central_difference(f, x, eps=1e-6):
    """Central differences of ``f`` at ``x``, one column per coordinate, as one
    compiled program (op by op, a system's functions take seconds)."""
    steps = eps * jnp.eye(x.shape[0], dtype=x.dtype)
    columns = jax.jit(jax.vmap(lambda d: (f(x + d) - f(x - d)) / (2 * eps)))(steps)
    return np.moveaxis(np.asarray(columns), 0, -1)


def test_constraint_jacobian_and_tangents_against_finite_differences():
    model = mechanism().model()
    q, v = random_state(model)
    G = jax.jit(lambda x: model.constraint_jacobian(x))(q)
    np.testing.assert_allclose(G, central_difference(model.constraints, q), rtol=1e-6, atol=1e-7)
    K, C = jax.jit(lambda x, y: model.tangents(x, y, 0.3))(q, v)
    np.testing.assert_allclose(-K, central_difference(lambda x: model.force(x, v, 0.3), q), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(-C, central_difference(lambda y: model.force(q, y, 0.3), v), rtol=1e-5, atol=1e-6)


def test_derived_structure_is_what_the_functions_do():
    model = mechanism().model()
    q, v = random_state(model)
    checked = nj.check_model(model, q, v, spread=0.01)
    assert {"sizes", "mass_product", "tangents", "constant_mass"} <= set(checked)
    assert (model.constant_mass, model.linear_force, model.velocity_dependent_force,
            model.linear_constraints) == (True, False, True, False)
    assert model.n_dof == 3 + 9 + 3 + 2
    assert model.n_bilateral == 2 + 3 + 2 + 1 and model.n_unilateral == 2 + 2 + 1
    assert not model.has_energy  # prescribed loads are not conservative


@pytest.mark.parametrize("build, flags", [
    # point masses against planes, pinned to the ground: all affine
    (lambda s: (s.add_body("m", PointMass(1.0, [0.0, 1.0])),
                s.add_contact("c", PlaneContact("m", normal=[0.0, 1.0], origin=[0.0, 0.0], e=0.5))),
     dict(linear_force=True, linear_constraints=True, velocity_dependent_force=False)),
    # a beam node pinned to the ground: affine constraints, nonlinear elastic force
    (lambda s: (s.add_body("b", Beam2D(1e6, 0.3, 1e3, 1e-3, 1e-8, 1.0, 3)),
                s.add_joint("p", Pin("ground", "b", node_b=0))),
     dict(linear_force=False, linear_constraints=True, velocity_dependent_force=False)),
    # a rigid body's offset point: nonlinear constraint, a spring-damper: velocity dependent
    (lambda s: (s.add_body("r", RigidBody2D(1.0, 0.1, [0.5, 0.0])),
                s.add_joint("p", Pin("ground", "r", at_b=[-0.5, 0.0])),
                s.add_force("k", SpringDamper("ground", "r", 10.0, 0.5, damping=1.0, at_a=[1.0, 0.0]))),
     dict(linear_force=False, linear_constraints=False, velocity_dependent_force=True)),
])
def test_flags_follow_the_parts(build, flags):
    s = System(dim=2, gravity=[0.0, -9.81])
    build(s)
    model = s.model()
    for name, value in flags.items():
        assert getattr(model, name) is value, name
    q, v = random_state(model)
    nj.check_model(model, q, v, spread=0.01)


def test_joints_hold_and_contacts_do_not_penetrate_through_a_run():
    """A double pendulum of rigid links pinned in series against a wall:
    bilateral violations at Newton tolerance, no penetration beyond it."""
    s = System(dim=2, gravity=[0.0, -9.81])
    s.add_body("upper", RigidBody2D(1.0, 1.0 / 12, [0.5, 0.0]))
    s.add_body("lower", RigidBody2D(1.0, 1.0 / 12, [1.5, 0.0]))
    s.add_joint("shoulder", Pin("ground", "upper", at_b=[-0.5, 0.0]))
    s.add_joint("elbow", Pin("upper", "lower", at_a=[0.5, 0.0], at_b=[-0.5, 0.0]))
    s.add_contact("wall", PlaneContact("lower", normal=[1.0, 0.0], origin=[-0.3, 0.0], e=0.5,
                                       points=[[0.5, 0.0]]))
    model, q0, v0 = s.build()
    sol = nj.simulate(model, nj.DS(), 0.0, 1.2, 1e-3, q0, v0)
    g = np.asarray(jax.vmap(model.bilateral)(sol.q))
    w = np.asarray(jax.vmap(lambda q, v: model.constraint_jacobian(q)[:model.n_bilateral] @ v)(sol.q, sol.v))
    assert np.abs(g).max() < 1e-8 and np.abs(w).max() < 1e-7
    gaps = np.asarray(jax.vmap(model.unilateral)(sol.q))
    assert gaps.min() > -1e-8
    assert (gaps[:, 0] < 1e-6).any(), "the lower link's tip reaches the wall"
    energy = np.asarray(jax.vmap(model.energy)(sol.q, sol.v))
    assert np.diff(energy).max() < 1e-3 * np.abs(energy).max()


def test_initial_state_violations_are_named():
    s = System(dim=2)
    s.add_body("a", RigidBody2D(1.0, 0.1, [0.5, 0.0]))
    s.add_joint("pivot", Pin("ground", "a", at_b=[-0.4, 0.0]))
    with pytest.raises(nj.ConfigError, match=r"joints\.pivot: violated at the initial state by 0\.1 m"):
        s.build()
    s = System(dim=2)
    s.add_body("a", RigidBody2D(1.0, 0.1, [0.5, 0.0], velocity=[0.0, 1.0]))
    s.add_joint("pivot", Pin("ground", "a", at_b=[-0.5, 0.0]))
    with pytest.raises(nj.ConfigError, match=r"joints\.pivot: the initial velocities violate it"):
        s.build()
    s = System(dim=1)
    s.add_body("ball", PointMass(1.0, [-0.01]))
    s.add_contact("floor", PlaneContact("ball", normal=[1.0], origin=[0.0], e=0.5))
    with pytest.raises(nj.ConfigError, match=r"contacts\.floor: initial penetration of 0\.01 m at point 0"):
        s.build()


@pytest.mark.parametrize("add, message", [
    (lambda s: s.add_joint("j", Pin("ghost", "a")), r"joints\.j: body_a = 'ghost' names a body that does not exist"),
    (lambda s: s.add_contact("c", PlaneContact("ghost", normal=[0.0, 1.0], origin=[0.0, 0.0], e=0.5)),
     r"contacts\.c: body = 'ghost' names a body that does not exist \(bodies: a, m, ground\)"),
    # parts that nothing moves: a constant gap, constraint or force, refused before compiling
    (lambda s: s.add_contact("c", PlaneContact("ground", normal=[0.0, 1.0], origin=[0.0, 0.0], e=0.5)),
     r"contacts\.c: body = 'ground', the fixed frame; a contact needs a moving body \(one of: a, m\)"),
    (lambda s: s.add_contact("c", SphereContact("ground", "ground", 0.1, 0.1, 0.5, at_b=[1.0, 0.0])),
     r"contacts\.c: body_a = body_b = 'ground', the fixed frame; a contact needs a moving body"),
    (lambda s: s.add_joint("j", Pin("ground", "ground")), r"joints\.j: body_a = body_b = 'ground'.*a joint needs"),
    (lambda s: s.add_force("f", SpringDamper("ground", "ground", 1.0, 1.0, at_b=[1.0, 0.0])),
     r"forces\.f: body_a = body_b = 'ground'.*acts on nothing"),
    (lambda s: s.add_force("f", Gravity([0.0, -9.81], on=("ground",))), r"forces\.f: on = 'ground'"),
    (lambda s: s.add_joint("j", Pin("a", "a", at_b=[0.5, 0.0])),
     r"joints\.j: body_a = body_b = 'a', a rigid body; .* its constraint is a constant"),
    (lambda s: s.add_contact("c", SphereContact("m", "m", 0.1, 0.1, 0.5)),
     r"contacts\.c: body_a = body_b = 'm', a rigid body; .* its gap is a constant"),
    (lambda s: s.add_joint("j", Pin("ground", "a", at_b=[0.0, 0.0, 1.0])), r"joints\.j: anchor b .*2 coordinates"),
    (lambda s: s.add_contact("c", PlaneContact("a", normal=[0.0, 1.0], origin=[0.0, 0.0], e=0.5, nodes=[0])),
     r"contacts\.c: a rigid body's points are named by points"),
    (lambda s: s.add_joint("j", Weld("ground", "m")), r"joints\.j: body b \(PointMass\) has no orientation"),
    (lambda s: s.add_force("f", Gravity([0.0, 0.0, -9.81])), r"forces\.f: acceleration has 3 coordinates"),
    (lambda s: s.add_body("far", PointMass(1.0, [0.0, 0.0, 0.0])), r"bodies\.far: lives in 3 dimensions"),
])
def test_wrong_references_and_anchors_are_named(add, message):
    s = System(dim=2)
    s.add_body("a", RigidBody2D(1.0, 0.1, [0.0, 0.0]))
    s.add_body("m", PointMass(1.0, [0.0, 1.0]))
    add(s)
    with pytest.raises(nj.ConfigError, match=message):
        s.model()


def test_a_part_on_the_ground_is_refused_even_when_its_values_are_traced():
    """The references are structure: checked where the values are traced too
    (a system built inside a gradient), where the value rules are not."""
    def build(e):
        s = System(dim=2)
        s.add_body("m", PointMass(1.0, [0.0, 1.0]))
        s.add_contact("c", PlaneContact("ground", normal=[0.0, 1.0], origin=[0.0, 0.0], e=e))
        return s.model().restitution.sum()

    with pytest.raises(nj.ConfigError, match=r"contacts\.c: body = 'ground'"):
        jax.grad(build)(0.5)


def test_joints_between_nodes_of_one_flexible_body_stand():
    s = System(dim=2)
    s.add_body("beam", Beam2D(E=2e9, nu=0.3, rho=1000.0, area=1e-4, second_moment=1e-9, length=1.0, n_elements=4))
    s.add_joint("ring", Distance("beam", "beam", node_a=0, node_b=4, length=1.0))
    assert s.model().n_bilateral == 1


def test_names_and_fields_are_checked_when_added():
    s = System(dim=2)
    with pytest.raises(nj.ConfigError, match="'ground' is the fixed frame's name"):
        s.add_body("ground", PointMass(1.0, [0.0, 0.0]))
    with pytest.raises(nj.ConfigError, match="must be an identifier"):
        s.add_body("two words", PointMass(1.0, [0.0, 0.0]))
    s.add_body("a", PointMass(1.0, [0.0, 0.0]))
    with pytest.raises(nj.ConfigError, match=r"bodies\.a: the name is used twice"):
        s.add_body("a", PointMass(1.0, [0.0, 0.0]))
    with pytest.raises(nj.ConfigError, match="expected a AbstractJoint"):
        s.add_joint("j", PointMass(1.0, [0.0, 0.0]))
    with pytest.raises(nj.ConfigError, match=r"PointMass\.mass_ must be in \(0, inf\)"):
        PointMass(-1.0, [0.0, 0.0])
    with pytest.raises(nj.ConfigError, match=r"PlaneContact\.e must be in \[0, 1\]"):
        PlaneContact("a", normal=[0.0, 1.0], origin=[0.0, 0.0], e=1.5)
    with pytest.raises(nj.ConfigError, match="gravity must have 2 coordinates"):
        System(dim=2, gravity=[0.0, 0.0, -9.81])


def test_rows_and_coordinates_name_the_parts():
    model = mechanism().model()
    assert model.coordinates("beam") == slice(3, 12)
    assert model.rows("joints", "clamp") == slice(2, 5)
    assert model.rows("contacts", "floor") == slice(8 + 2, 8 + 4)
    q, _ = random_state(model)
    np.testing.assert_array_equal(model.constraints(q)[model.rows("contacts", "floor")],
                                  q[model.coordinates("beam")][jnp.array([4, 7])] + 0.5)


def chain(n_links: int, length: float = 0.3) -> System:
    """Links pinned in series: many parts of one kind, evaluated as groups."""
    s = System(dim=2, gravity=[0.0, -9.81])
    for i in range(n_links):
        s.add_body(f"l{i}", RigidBody2D(1.0 + 0.1 * i, 0.01, [(i + 0.5) * length, 0.0]))
        parent = "ground" if i == 0 else f"l{i - 1}"
        s.add_joint(f"p{i}", Pin(parent, f"l{i}", at_a=[0.0 if i == 0 else length / 2, 0.0], at_b=[-length / 2, 0.0]))
        s.add_force(f"k{i}", TorsionalSpring(parent, f"l{i}", 2.0 + i, damping=0.1))
    s.add_contact("wall", PlaneContact(f"l{n_links - 1}", normal=[1.0, 0.0], origin=[-1.0, 0.0], e=0.5,
                                       points=[[length / 2, 0.0], [-length / 2, 0.0]]))
    return s


@pytest.mark.parametrize("system", [chain(4), mechanism()], ids=["chain", "mechanism"])
def test_second_derivatives_against_finite_differences(system):
    """The curvature d(g_q^T mu)/dq and G^s = d(g_q v)/dq (eq. 50), part by part
    and in groups, against differences of the constraint Jacobian."""
    model = system.model()
    q, v = random_state(model, seed=1)
    mu = jnp.asarray(np.random.default_rng(2).standard_normal(model.n_constraints))
    G = jax.jit(lambda x: model.constraint_jacobian(x))
    curvature = jax.jit(lambda x, m: model.constraint_curvature(x, m))(q, mu)
    np.testing.assert_allclose(curvature, central_difference(lambda x: G(x).T @ mu, q), rtol=1e-5, atol=1e-6)
    velocity_gradient = jax.jit(lambda x, y: model.velocity_constraint_gradient(x, y))(q, v)
    np.testing.assert_allclose(velocity_gradient, central_difference(lambda x: G(x) @ v, q), rtol=1e-5, atol=1e-6)
    nb = model.n_bilateral
    bilateral = jax.jit(lambda x, y: (model.velocity_constraint_gradient(x, y, bilateral_only=True),
                                      model.bilateral_jacobian(x)))
    gradient, jacobian = bilateral(q, v)
    np.testing.assert_allclose(gradient, jax.jit(lambda x, y: model.velocity_constraint_gradient(x, y))(q, v)[:nb],
                               rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(jacobian, G(q)[:nb], rtol=1e-12, atol=1e-14)


def test_grouped_parts_equal_their_members_one_by_one():
    """A chain's pins, torsional springs and bodies, evaluated by one vmap per
    kind, against each part evaluated alone."""
    model = chain(5).model()
    q, v = random_state(model, seed=3)
    slices = [model.coordinates(name) for name in model.body_names]
    one_by_one = []
    for joint in model.joints:
        bodies = tuple(model.body(name) for name in joint.bodies)
        one_by_one.append(joint.evaluate(bodies, tuple(q[model.coordinates(n)] if n != "ground" else q[:0]
                                                       for n in joint.bodies)))
    np.testing.assert_allclose(model.bilateral(q), jnp.concatenate(one_by_one), rtol=1e-14, atol=1e-15)
    f = jnp.zeros_like(q)
    for force in model.forces:
        bodies = tuple(model.body(name) for name in force.bodies)
        local = force.generalized(bodies, tuple(q[model.coordinates(n)] if n != "ground" else q[:0]
                                                for n in force.bodies),
                                  tuple(v[model.coordinates(n)] if n != "ground" else v[:0] for n in force.bodies), 0.0)
        for name, fb in zip(force.bodies, local):
            if name != "ground":
                f = f.at[model.coordinates(name)].add(fb)
    np.testing.assert_allclose(model.force(q, v, 0.0), f, rtol=1e-13, atol=1e-13)
    M = jax.scipy.linalg.block_diag(*[model.body(n).mass(q[s]) for n, s in zip(model.body_names, slices)])
    np.testing.assert_array_equal(model.mass(q), M)
